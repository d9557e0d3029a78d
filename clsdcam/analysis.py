"""The paper's analysis of a design: resolution from the PSF, local condition numbers, and
reconstructions of spectral accuracy, two-point resolution and the three designs.

- Two-point resolution from the PSF: the half-width r₇₀ of the PSF autocorrelation
  (h ⋆ h)(Δ) at 70 % of its peak (:func:`clsdcam.sim.autocorrelation_halfwidth`), in pixels
  and in super-pixels of 16 px (paper: ~3 px = 0.19 super-pixel).
- Local condition numbers: for a group S of voxels, κ(A_S) = σ_max/σ_min of the sub-matrix of
  A made of their columns. Column (k, y, x) is the image of a unit point of band k at sensor
  pixel (y, x): a_{k,y,x} = F_k ⊙ h(· − (y, x) + c), the PSF moved so that its centre
  c = (H//2, W//2) lands on (y, x) (equal to A applied to the unit voxel; tested) — A is
  never formed. 2-D: n points on a grid of spacing d in one band; 3-D: the same points in
  two adjacent bands (2n columns). κ is averaged geometrically over random placements.
- Reconstruction analyses (the default solver, with the default weights, on simulated frames):
  spectral accuracy of narrow-band points, two-point resolution by the Rayleigh criterion, and the
  diffuser against low- and high-NA lenses on the same filter array.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sim
from .camera.calibration import Calibration
from .camera.raw import bin_pixels, shift_image
from .metrics import psnr, spectral_angle
from .sim.scenes import SOURCE_FWHM, source_cube, source_lines, source_positions
from .solve.solver import reconstruct

COND_LIMIT = 40.0
RAYLEIGH_DIP = 0.735          # resolved when the dip between two peaks is ≤ 73.5 % of the weaker peak
TWO_POINT_WAVELENGTHS = (618.0, 522.0, 466.0)
LINE_FWHM = SOURCE_FWHM       # nm, the narrow-band sources of the spectral and two-point analyses
NOISE_VAR, PHOTONS = 1e-5, 20000.0   # the simulator's default read and shot noise
SINGULAR = 1.0 / np.finfo(np.float64).eps   # κ reported for numerically singular groups


# ---- resolution from the PSF ------------------------------------------------------------------
@dataclass(frozen=True)
class Resolution:
    pixels: float        # r₇₀, px
    superpixels: float   # r₇₀ / 16


def autocorrelation_resolution(psf: np.ndarray, level: float = 0.7) -> Resolution:
    """r such that (h ⋆ h)(r·u) = level · (h ⋆ h)(0), averaged over directions u; px and super-pixels."""
    pixels = sim.autocorrelation_halfwidth(np.asarray(psf, np.float64), level=level)
    return Resolution(pixels, pixels / sim.SUPERPIXEL_PX)


def dark_level(image: np.ndarray, fraction: float = 0.03) -> float:
    """Median of the outer frame ring (``fraction`` of each side, ≥ 1 px): the sensor's dark level
    outside the caustic (the frame median is not: a lensless PSF fills much of the frame)."""
    ring = np.ones(image.shape, bool)
    by, bx = (max(1, int(fraction * n)) for n in image.shape)
    ring[by:-by, bx:-bx] = False
    return float(np.median(image[ring]))


def binning_factor(shape, target=sim.DEFAULT_SHAPE) -> int:
    """The smallest integer f with H/f ≤ target H and W/f ≤ target W (the prototype's sensor scale)."""
    return max(1, int(np.ceil(max(s / t for s, t in zip(shape, target)))))


def measured_psf(raw: np.ndarray, target=sim.DEFAULT_SHAPE) -> tuple[np.ndarray, int]:
    """A raw PSF frame made comparable with the simulated one: max(raw − dark, 0), binned by
    :func:`binning_factor` to the prototype's 320 × 448 scale. Returns (psf, f)."""
    raw = np.asarray(raw, np.float64)
    factor = binning_factor(raw.shape, target)
    return bin_pixels(np.maximum(raw - dark_level(raw), 0.0), factor), factor


# ---- columns of A and local condition numbers ---------------------------------------------------
def point_image(psf: np.ndarray, y: int, x: int) -> np.ndarray:
    """h(p − (y, x) + c): the sensor image of a unit point at (y, x), c = (H//2, W//2); zero fill."""
    return shift_image(np.asarray(psf, np.float64), (y - psf.shape[0] // 2, x - psf.shape[1] // 2))


def columns(psf, filters, voxels) -> np.ndarray:
    """A_S: the columns a_{k,y,x} = F_k ⊙ h(· − (y, x) + c) for voxels (k, y, x), as (pixels, |S|) float64."""
    return np.stack([(filters[k] * point_image(psf, y, x)).ravel() for k, y, x in voxels], axis=1)


def grid_points(n: int, separation: int, origin) -> list[tuple[int, int]]:
    """n points, row by row, on a ⌈√n⌉-wide square grid of spacing ``separation`` from ``origin``."""
    side = int(np.ceil(np.sqrt(n)))
    return [(origin[0] + separation * (i // side), origin[1] + separation * (i % side)) for i in range(n)]


def group_voxels(n: int, separation: int, band: int, origin, spectral: bool = False) -> list[tuple[int, int, int]]:
    """The voxels of a group: n grid points in ``band`` (2-D), and also in ``band + 1`` (3-D)."""
    bands = (band, band + 1) if spectral else (band,)
    return [(k, y, x) for k in bands for y, x in grid_points(n, separation, origin)]


def local_condition(matrix: np.ndarray) -> float:
    """κ(M) = σ_max/σ_min over the rows where some column is non-zero (the others add nothing to MᵀM).

    Computed as numpy.linalg.cond(R) of M = QR (Q has orthonormal columns, so M and R share
    their singular values); fewer rows than columns is singular. Capped at 1/ε.
    """
    support = matrix[np.any(matrix != 0, axis=1)]
    if support.shape[0] < support.shape[1]:
        return SINGULAR
    return float(min(np.linalg.cond(np.linalg.qr(support, mode="r")), SINGULAR))


def group_condition(psf, filters, n: int, separation: int, band: int, origin, spectral: bool = False) -> float:
    """κ(A_S) for the group of :func:`group_voxels`."""
    return local_condition(columns(psf, filters, group_voxels(n, separation, band, origin, spectral)))


def placements(rng: np.random.Generator, filters_shape, span: int, spectral: bool, trials: int):
    """``trials`` random (band, origin): band uniform (its successor must exist in 3-D), the grid's
    corner uniform in the central half of the frame so that a grid ``span`` px wide stays inside it."""
    k, h, w = filters_shape

    def corner(size):
        return int(rng.integers(size // 4, max(size // 4 + 1, 3 * size // 4 - span)))

    return [(int(rng.integers(0, k - 1 if spectral and k > 1 else k)), (corner(h), corner(w))) for _ in range(trials)]


def condition_sweep(psf, filters, separations, n: int = 4, spectral: bool = False, trials: int = 5,
                    seed: int = 0) -> np.ndarray:
    """Geometric mean exp(mean_t log κ(A_{S_t}(d))) over the same ``trials`` placements, for each d."""
    grid_span = max(separations) * (int(np.ceil(np.sqrt(n))) - 1)
    places = placements(np.random.default_rng(seed), filters.shape, grid_span, spectral, trials)
    return np.array([np.exp(np.mean([np.log(group_condition(psf, filters, n, d, band, origin, spectral))
                                     for band, origin in places])) for d in separations])


def separation_below(separations, conditions, limit: float = COND_LIMIT):
    """The smallest separation from which every larger one keeps κ ≤ limit (None if never)."""
    ok = np.asarray(conditions) <= limit
    for i in range(len(ok)):
        if ok[i:].all():
            return separations[i]
    return None


def condition_study(psfs: dict, filters, separations, counts=(2, 4, 9, 16), trials: int = 5, seed: int = 0) -> dict:
    """For each design (name -> PSF), 2-D and 3-D, and group size n: κ against d and the d at κ = 40."""
    study = {}
    for design, psf in psfs.items():
        psf = np.asarray(psf, np.float64)
        for mode, spectral in (("2-D", False), ("3-D", True)):
            for n in counts:
                cond = condition_sweep(psf, filters, separations, n, spectral, trials, seed)
                study[f"{design}|{mode}|{n}"] = {"design": design, "mode": mode, "points": n,
                                                 "condition": cond.tolist(),
                                                 "separation_at_limit_px": separation_below(separations, cond)}
    return study


# ---- reconstruction analyses ----------------------------------------------------------------------
def camera(shape, n_bands: int, seed: int, psf=None) -> Calibration:
    """A simulated camera: ``psf`` (default the caustic) over the default filter array."""
    wavelengths = sim.band_wavelengths(n_bands)
    psf = sim.caustic_psf(shape, seed) if psf is None else np.asarray(psf, np.float32)
    return Calibration(psf, sim.filter_array(shape, wavelengths, seed), wavelengths, source="clsdcam.analysis")


def simulate_and_reconstruct(truth: np.ndarray, calibration: Calibration, iters: int, seed: int) -> np.ndarray:
    """b = A v + shot and read noise (the simulator's defaults), clipped at 0; the solver's cube."""
    clean = sim.noiseless_measurement(calibration.psf, calibration.filters, truth)
    noisy = sim.add_noise(clean, np.random.default_rng(seed), NOISE_VAR, PHOTONS)
    return reconstruct(np.maximum(noisy, 0.0).astype(np.float32), calibration, iters=iters).cube


def line_spectrum(centre: float, wavelengths) -> np.ndarray:
    """Band averages of a Gaussian line of LINE_FWHM nm at ``centre``."""
    return sim.band_average(sim.gaussian_line(centre, LINE_FWHM), wavelengths)


def peak_wavelength(spectrum, wavelengths) -> float:
    """The peak by three-point Gaussian interpolation around the brightest band i:
    δ = ½ (ln a − ln c) / (ln a − 2 ln b + ln c) for samples a, b, c at i−1, i, i+1 (exact for a
    Gaussian on uniform bands; a parabola on the values when one is ≤ 0), then λ(i + δ), |δ| ≤ 1."""
    spectrum = np.asarray(spectrum, np.float64)
    i = int(np.clip(np.argmax(spectrum), 1, len(spectrum) - 2))
    a, b, c = spectrum[i - 1:i + 2]
    if min(a, b, c) > 0:
        a, b, c = np.log([a, b, c])
    curvature = a - 2 * b + c
    shift = 0.5 * (a - c) / curvature if curvature < 0 else 0.0
    return float(np.interp(i + np.clip(shift, -1, 1), np.arange(len(wavelengths)), wavelengths))


def spectral_accuracy(shape=(64, 96), n_bands: int = 64, n_sources: int = 16, iters: int = 200, seed: int = 0) -> dict:
    """Single-pixel sources of 10 nm lines at n_sources wavelengths evenly over the band centres
    (390–894 nm at 64 bands), all in one frame (the simulator's ``sources`` scene), one reconstruction;
    each source's peak found by :func:`peak_wavelength` on the spectrum summed over its 3 × 3 neighbourhood."""
    calibration = camera(shape, n_bands, seed)
    wavelengths = calibration.wavelengths
    centres, positions = source_lines(wavelengths, n_sources), source_positions(shape, n_sources)
    cube = simulate_and_reconstruct(source_cube(shape, wavelengths, n_sources).astype(np.float32), calibration,
                                    iters, seed)
    found = np.array([peak_wavelength(cube[:, y - 1:y + 2, x - 1:x + 2].sum(axis=(1, 2)), wavelengths)
                      for y, x in positions])
    errors = found - centres
    return {"true_nm": centres.tolist(), "found_nm": found.tolist(), "error_nm": errors.tolist(),
            "median_abs_error_nm": float(np.median(np.abs(errors))), "worst_abs_error_nm": float(np.abs(errors).max()),
            "positions": [list(p) for p in positions], "shape": list(shape), "bands": n_bands, "iters": iters}


def dip_ratio(profile, left: int, right: int) -> float:
    """Rayleigh measure of a profile with points at ``left`` < ``right``: min(profile strictly between)
    / min(peak_left, peak_right), each peak the max of the point's pixel and its outer neighbour.
    Resolved when ≤ RAYLEIGH_DIP (the Airy pattern's 73.5 %); points 1 px apart have no dip (1.0)."""
    profile = np.asarray(profile, np.float64)
    if right - left < 2:
        return 1.0
    peaks = min(profile[max(left - 1, 0):left + 1].max(), profile[right:right + 2].max())
    return float(profile[left + 1:right].min() / peaks) if peaks > 0 else 1.0


def pair_layout(shape, separations) -> list[tuple[int, int]]:
    """Left points (y, x) of one pair per separation, in two columns of rows spread over the frame."""
    rows = int(np.ceil(len(separations) / 2))
    ys = np.round(np.linspace(shape[0] / 6, 5 * shape[0] / 6, rows)).astype(int)
    xs = (shape[1] // 4 - max(separations) // 2, 3 * shape[1] // 4 - max(separations) // 2)
    return [(int(ys[i % rows]), int(xs[i // rows])) for i in range(len(separations))]


def two_point_resolution(shape=(64, 96), n_bands: int = 64, separations=tuple(range(2, 9)), iters: int = 200,
                         seed: int = 0) -> dict:
    """Per wavelength (618, 522, 466 nm lines), one frame holding one pair of single-pixel points
    per separation d (in x, pairs ≥ shape/6 apart), one reconstruction; the band-summed row through
    each pair gives :func:`dip_ratio`; the resolution is the smallest d from which every larger
    d is resolved (dip ≤ 0.735 of the weaker peak)."""
    calibration = camera(shape, n_bands, seed)
    lefts = pair_layout(shape, separations)
    out = {"separations_px": list(separations), "criterion": RAYLEIGH_DIP, "shape": list(shape), "iters": iters}
    for line in TWO_POINT_WAVELENGTHS:
        truth = np.zeros((n_bands,) + tuple(shape), np.float32)
        for (y, x), d in zip(lefts, separations):
            truth[:, y, x] = truth[:, y, x + d] = line_spectrum(line, calibration.wavelengths)
        image = simulate_and_reconstruct(truth, calibration, iters, seed).sum(axis=0)
        dips = [dip_ratio(image[y], x, x + d) for (y, x), d in zip(lefts, separations)]
        out[f"{line:g}"] = {"dip_ratio": dips,
                            "resolved_px": separation_below(list(separations), dips, RAYLEIGH_DIP)}
    return out


def design_comparison(shape=(64, 96), n_bands: int = 64, iters: int = 200, seed: int = 0) -> dict:
    """The target under red, green, blue and white light through each design of
    :data:`clsdcam.sim.DESIGNS` (same filters, noise and solver settings): PSNR, mean spectral
    angle, and the cubes for the pictures."""
    rows = {}
    for name, build in sim.DESIGNS.items():
        simulation = sim.simulate("target", shape, n_bands, seed, psf=build(shape, seed))
        cube = reconstruct(simulation.measurement, simulation.calibration, iters=iters).cube
        rows[name] = {"psnr": psnr(cube, simulation.truth), "angle": spectral_angle(cube, simulation.truth),
                      "cube": cube, "wavelengths": simulation.calibration.wavelengths, "truth": simulation.truth}
    return rows
