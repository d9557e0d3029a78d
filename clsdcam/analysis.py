"""The paper's analysis of a design: resolution from the PSF, local condition numbers, and
reconstructions of resolution, spectral accuracy and design comparisons.

- Two-point resolution from the PSF: half-width of the PSF autocorrelation at 70 % of its peak
  (paper: ~3 px, 0.19 super-pixel).
- Local condition numbers: for n point sources on a grid with separation d, cond(A_S) of the
  sub-matrix of A made of their columns. Column (k, y, x) is the image of a unit point of band
  k at sensor pixel (y, x): F_k ⊙ h(· − (y, x) + c), the PSF moved so that its centre c lands
  on (y, x) — A is never formed. 2-D: one band; 3-D: the same points in two adjacent bands.
- Reconstruction analyses (the solver with default settings on simulated scenes): spectral
  accuracy of narrow-band points, two-point resolution by the Rayleigh criterion, and the
  diffuser against low- and high-NA lenses.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import sim
from .calibration import Calibration
from .metrics import psnr, spectral_angle
from .solver import reconstruct

COND_LIMIT = 40.0
RAYLEIGH_DIP = 0.735          # resolved when the dip between two peaks is ≤ 73.5 % of the weaker peak
TWO_POINT_WAVELENGTHS = (618.0, 522.0, 466.0)


@dataclass(frozen=True)
class Resolution:
    pixels: float
    superpixels: float


def autocorrelation_resolution(psf: np.ndarray, level: float = 0.7) -> Resolution:
    """Half-width of the PSF autocorrelation at ``level`` of its peak, in pixels and super-pixels."""
    pixels = sim.autocorrelation_halfwidth(np.asarray(psf, np.float64), level=level)
    return Resolution(pixels, pixels / sim.SUPERPIXEL_PX)


# ---- columns of A and condition numbers ------------------------------------------------------
def point_image(psf: np.ndarray, y: int, x: int) -> np.ndarray:
    """h(p − (y, x) + c): the sensor image of a unit point at (y, x), c = (H//2, W//2); zero fill."""
    h, w = psf.shape
    dy, dx = y - h // 2, x - w // 2
    out = np.zeros_like(psf, dtype=np.float64)
    out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = psf[max(-dy, 0):h - max(dy, 0), max(-dx, 0):w - max(dx, 0)]
    return out


def columns(psf, filters, voxels) -> np.ndarray:
    """The columns of A for voxels (k, y, x) on the sensor window, as a (pixels, n) matrix."""
    return np.stack([(filters[k] * point_image(psf, y, x)).ravel() for k, y, x in voxels], axis=1)


def grid_points(n: int, separation: int, origin) -> list[tuple[int, int]]:
    """n points on a ⌈√n⌉-wide square grid of spacing ``separation`` from ``origin``."""
    side = int(np.ceil(np.sqrt(n)))
    return [(origin[0] + separation * (i // side), origin[1] + separation * (i % side)) for i in range(n)]


def group_condition(psf, filters, n: int, separation: int, band: int, origin, spectral: bool = False) -> float:
    """cond(A_S) for n grid points in ``band`` (and ``band + 1`` when ``spectral``): 2-D or 3-D."""
    bands = (band, band + 1) if spectral else (band,)
    voxels = [(k, y, x) for k in bands for y, x in grid_points(n, separation, origin)]
    matrix = columns(psf, filters, voxels)
    return float(np.linalg.cond(matrix[np.any(matrix != 0, axis=1)])) if matrix.any() else np.inf


def condition_sweep(psf, filters, separations, n: int = 4, spectral: bool = False, trials: int = 11,
                    seed: int = 0) -> np.ndarray:
    """Median over ``trials`` random positions and bands of cond(A_S), for each separation."""
    rng = np.random.default_rng(seed)
    k, h, w = filters.shape
    span = max(separations) * int(np.ceil(np.sqrt(n)))
    result = []
    for d in separations:
        values = [group_condition(psf, filters, n, d, int(rng.integers(0, k - 1 if spectral else k)),
                                  (int(rng.integers(h // 4, max(h // 4 + 1, 3 * h // 4 - span))),
                                   int(rng.integers(w // 4, max(w // 4 + 1, 3 * w // 4 - span)))), spectral)
                  for _ in range(trials)]
        result.append(np.median(values))
    return np.array(result)


def separation_below(separations, conditions, limit: float = COND_LIMIT):
    """The smallest separation from which every larger one keeps cond ≤ limit (None if never)."""
    ok = np.asarray(conditions) <= limit
    for i in range(len(ok)):
        if ok[i:].all():
            return separations[i]
    return None


# ---- reconstruction analyses ---------------------------------------------------------------
def spectral_accuracy(shape=(64, 64), n_bands: int = 64, n_sources: int = 9, iters: int = 200, seed: int = 0) -> dict:
    """Narrow-band (10 nm) point sources at wavelengths across the range, one reconstruction;
    the recovered peak (parabolic fit around the brightest band of the 3×3 sum) against the truth."""
    wavelengths = sim.band_wavelengths(n_bands)
    centres = np.linspace(wavelengths[2], wavelengths[-3], n_sources)
    positions = grid_points(n_sources, max(4, min(shape) // 4), (shape[0] // 6, shape[1] // 6))
    truth = np.zeros((n_bands,) + tuple(shape), np.float32)
    for (y, x), centre in zip(positions, centres):
        truth[:, y, x] = sim.band_average(sim.gaussian_line(centre, 10.0), wavelengths)
    cube = _reconstruct_scene(truth, shape, n_bands, seed, sim.caustic_psf(shape, seed), iters)
    found = np.array([_peak_wavelength(cube[:, y - 1:y + 2, x - 1:x + 2].sum(axis=(1, 2)), wavelengths)
                      for y, x in positions])
    errors = np.abs(found - centres)
    return {"true_nm": centres.tolist(), "found_nm": found.tolist(), "error_nm": errors.tolist(),
            "median_error_nm": float(np.median(errors)), "worst_error_nm": float(errors.max())}


def _peak_wavelength(spectrum, wavelengths) -> float:
    """Vertex of the parabola through the brightest band and its neighbours."""
    i = int(np.clip(np.argmax(spectrum), 1, len(spectrum) - 2))
    a, b, c = spectrum[i - 1:i + 2]
    shift = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
    return float(np.interp(i + np.clip(shift, -1, 1), np.arange(len(wavelengths)), wavelengths))


def _reconstruct_scene(truth, shape, n_bands, seed, psf, iters) -> np.ndarray:
    """Simulate the camera (given PSF, default filters, default noise) on ``truth`` and reconstruct."""
    filters = sim.filter_array(shape, sim.band_wavelengths(n_bands), seed)
    measurement = sim.add_noise(sim.noiseless_measurement(psf, filters, truth), np.random.default_rng(seed), 1e-5)
    calibration = Calibration(psf, filters, sim.band_wavelengths(n_bands), source="analysis")
    return reconstruct(np.maximum(measurement, 0), calibration, iters=iters).cube


def two_point_resolution(shape=(32, 48), n_bands: int = 64, separations=range(2, 9), iters: int = 200,
                         seed: int = 0) -> dict:
    """Per wavelength, the smallest separation (px) at which two reconstructed points are resolved:
    the band-summed profile through them dips to ≤ RAYLEIGH_DIP of the weaker peak between them."""
    wavelengths = sim.band_wavelengths(n_bands)
    psf = sim.caustic_psf(shape, seed)
    out = {}
    for line in TWO_POINT_WAVELENGTHS:
        spectrum = sim.band_average(sim.gaussian_line(line, 10.0), wavelengths)
        resolved = None
        for d in separations:
            y, x0 = shape[0] // 2, shape[1] // 2 - d // 2
            truth = np.zeros((n_bands,) + tuple(shape), np.float32)
            truth[:, y, x0] = truth[:, y, x0 + d] = spectrum
            profile = _reconstruct_scene(truth, shape, n_bands, seed, psf, iters).sum(axis=0)[y, x0:x0 + d + 1]
            if profile[1:-1].min() <= RAYLEIGH_DIP * min(profile[0], profile[-1]):
                resolved = d
                break
        out[f"{line:g}"] = resolved
    return out


def design_comparison(shape=(64, 96), n_bands: int = 64, iters: int = 200, seed: int = 0) -> dict:
    """The target under red, green, blue and white light through each design (same filters and
    settings): PSNR and mean spectral angle, and the cubes for the pictures."""
    rows = {}
    for name, build in sim.DESIGNS.items():
        simulation = sim.simulate("target", shape, n_bands, seed, psf=build(shape, seed))
        cube = reconstruct(simulation.measurement, simulation.calibration, iters=iters).cube
        rows[name] = {"psnr": psnr(cube, simulation.truth), "angle": spectral_angle(cube, simulation.truth),
                      "cube": cube, "wavelengths": simulation.calibration.wavelengths}
    return rows
