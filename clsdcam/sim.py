"""A Spectral DiffuserCam simulator: caustic PSF, tiled spectral filter array, scenes, noise.

The camera (Monakhova et al., Optica 2020): a bare sensor under an 8×8 tile of 64
narrow-band filters (each ``filter_px`` × ``filter_px`` pixels, 386–898 nm) and a smooth
random diffuser whose caustic pattern is the PSF h. A scene cube v (K, H, W) on the sensor
window gives the measurement

    b = Σ_k F_k ⊙ crop(h ∗ v_k) + noise,

computed with :class:`clsdcam.model.ForwardModel` (PSF origin at its centre pixel).

Spectral discretisation: filter responses are sampled at the band wavelengths,
F_k = T(λ_k); analytic scene spectra are band averages over each band's bin (so narrow
lines keep their energy at any band count); the real cube is linearly interpolated.
Every random choice is seeded; the same arguments give the same arrays.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import h5py
import numpy as np
import scipy.ndimage as ndi
from scipy.interpolate import interp1d

from .backends.numpy import NumpyBackend
from .calibration import Calibration
from .errors import InputError
from .io import save_measurement
from .model import ForwardModel

SPECTRAL_RANGE = (386.0, 898.0)    # nm, the prototype's calibrated range
DEFAULT_SHAPE = (320, 448)         # the published prototype's sensor crop
DEFAULT_BANDS = 64
N_FILTERS = 64
TILE = 8                           # the filter array is a TILE × TILE super-pixel
FWHM_RANGE = (6.0, 23.0)           # nm, filter FWHM from the bluest to the reddest filter
BORDER_FRACTION = 0.05             # scenes are zero within this fraction of each side
LINE_FWHM = 15.0                   # nm, narrow-band illumination in "target" and "points"
LED_FWHM = 20.0                    # nm
RGB_LINES = {"red": 630.0, "green": 530.0, "blue": 460.0}
SAMSON = "cubes/samson/samson_1.img"
SAMSON_SHAPE = (156, 95, 95)       # ENVI BSQ: bands, lines, samples


# ---- wavelengths ------------------------------------------------------------------------

def band_wavelengths(n_bands: int = DEFAULT_BANDS, lo: float = SPECTRAL_RANGE[0],
                     hi: float = SPECTRAL_RANGE[1]) -> np.ndarray:
    """Centres of ``n_bands`` equal bins over [lo, hi]: λ_k = lo + (k + ½)(hi − lo)/K (nm, float64).

    The defaults give 390, 398, …, 894 nm (8 nm bins), as in the paper's 64 bands.
    """
    if n_bands < 1:
        raise InputError(f"n_bands {n_bands}: must be ≥ 1")
    return lo + (np.arange(n_bands) + 0.5) * (hi - lo) / n_bands


def band_edges(wavelengths: np.ndarray) -> np.ndarray:
    """Bin edges (K+1,) around sorted band centres: midpoints, the ends mirrored.

    One band covers the whole SPECTRAL_RANGE (a panchromatic DiffuserCam).
    """
    centres = np.asarray(wavelengths, dtype=np.float64)
    if centres.size == 1:
        return np.array(SPECTRAL_RANGE)
    mids = 0.5 * (centres[1:] + centres[:-1])
    return np.concatenate([[2 * centres[0] - mids[0]], mids, [2 * centres[-1] - mids[-1]]])


def band_average(spectrum: Callable[[np.ndarray], np.ndarray], wavelengths, step_nm: float = 0.5) -> np.ndarray:
    """s_k = (1/|B_k|) ∫_{B_k} s(λ) dλ over each band's bin B_k (midpoint rule, ≤ step_nm apart)."""
    edges = band_edges(wavelengths)
    widths = np.diff(edges)
    n = max(4, int(np.ceil(widths.max() / step_nm)))
    grid = edges[:-1, None] + widths[:, None] * (np.arange(n) + 0.5) / n
    return spectrum(grid).mean(axis=1)


def gaussian_line(centre: float, fwhm: float) -> Callable[[np.ndarray], np.ndarray]:
    """s(λ) = exp(−4 ln2 (λ − centre)² / fwhm²): unit peak, full width ``fwhm`` at half maximum."""
    return lambda lam: np.exp(-4.0 * np.log(2.0) * (lam - centre) ** 2 / fwhm ** 2)


def blackbody(temperature_k: float = 5000.0) -> Callable[[np.ndarray], np.ndarray]:
    """Planck's law B(λ, T) ∝ λ⁻⁵ / (exp(hc/λkT) − 1), scaled to 1 at its peak λ = 2.898e6/T nm."""
    hc_over_k = 1.438777e7  # nm·K

    def radiance(lam):
        return lam ** -5.0 / np.expm1(hc_over_k / (lam * temperature_k))

    peak = radiance(2.897772e6 / temperature_k)
    return lambda lam: radiance(lam) / peak


# ---- the caustic PSF --------------------------------------------------------------------

def caustic_psf(shape=DEFAULT_SHAPE, seed: int = 0, smoothness: float = 8.0, strength: float = 2.0,
                aperture: float = 0.7, oversample: int = 4, blur: float = 0.7) -> np.ndarray:
    """The caustic of a smooth random diffuser: (H, W) float32, ≥ 0, ‖h‖₂ = 1.

    Surface: g = G_σ ∗ n, white noise n smoothed by a Gaussian of σ = ``smoothness`` px.
    Rays on a grid of ``oversample``² per pixel, inside a centred rectangle of ``aperture``
    times the frame, are deflected to p + c·∇g(p), with c = strength / rms(∇²g), so that
    ``strength`` is the rms of c·∇²g, the trace of the map's Jacobian minus 2 (caustic
    folds form where an eigenvalue of I + c·Hess g crosses 0). The landing points are
    binned per pixel and blurred by a Gaussian of ``blur`` px (pixel + diffraction).
    The defaults give an autocorrelation half-width (70 %) of about 3 px, the paper's.
    """
    spectrum = surface_spectrum(shape, np.random.default_rng(seed), smoothness)
    gy, gx = upsampled_gradient(spectrum, oversample)
    scale = strength / laplacian_rms(spectrum)
    inside = aperture_mask(shape, oversample, aperture)
    y, x = ray_grid(shape, oversample)
    counts = ray_histogram(y[inside] + scale * gy[inside], x[inside] + scale * gx[inside], shape)
    psf = ndi.gaussian_filter(counts, blur)
    return (psf / np.linalg.norm(psf)).astype(np.float32)


def frequency_grid(shape, spacing: float = 1.0):
    """(f_y column, f_x row) in cycles per pixel for an FFT grid of ``shape`` with sample ``spacing`` px."""
    return np.fft.fftfreq(shape[0], spacing)[:, None], np.fft.fftfreq(shape[1], spacing)[None, :]


def surface_spectrum(shape, rng: np.random.Generator, smoothness: float) -> np.ndarray:
    """ĝ = FFT(n) · exp(−2π²σ²|f|²): the spectrum of white noise smoothed by a Gaussian of σ px."""
    fy, fx = frequency_grid(shape)
    return np.fft.fft2(rng.standard_normal(shape)) * np.exp(-2.0 * np.pi ** 2 * smoothness ** 2 * (fy ** 2 + fx ** 2))


def laplacian_rms(spectrum: np.ndarray) -> float:
    """rms over the frame of ∇²g = IFFT(−4π²|f|² ĝ)."""
    fy, fx = frequency_grid(spectrum.shape)
    laplacian = np.fft.ifft2(-4.0 * np.pi ** 2 * (fy ** 2 + fx ** 2) * spectrum).real
    return float(np.sqrt(np.mean(laplacian ** 2)))


def upsampled_gradient(spectrum: np.ndarray, oversample: int):
    """(∂g/∂y, ∂g/∂x) per pixel on a grid ``oversample`` times finer, by zero-padding ĝ.

    Fine sample m is the surface at m/s + ½ in :func:`ray_grid` coordinates, ray m sits at
    (m + ½)/s: the random surface is merely shifted by less than half a pixel.
    """
    h, w = spectrum.shape
    fine_shape = (oversample * h, oversample * w)
    padded = np.zeros(fine_shape, complex)
    oy, ox = fine_shape[0] // 2 - h // 2, fine_shape[1] // 2 - w // 2
    padded[oy:oy + h, ox:ox + w] = np.fft.fftshift(spectrum)
    padded = np.fft.ifftshift(padded) * oversample ** 2
    fy, fx = frequency_grid(fine_shape, 1.0 / oversample)
    return tuple(np.fft.ifft2(2j * np.pi * f * padded).real for f in (fy, fx))


def ray_grid(shape, oversample: int):
    """Ray positions (y, x) in pixel units (pixel i covers [i, i+1)): (m + ½)/s on the fine grid."""
    y = (np.arange(oversample * shape[0]) + 0.5) / oversample
    x = (np.arange(oversample * shape[1]) + 0.5) / oversample
    return np.meshgrid(y, x, indexing="ij")


def aperture_mask(shape, oversample: int, aperture: float) -> np.ndarray:
    """Rays inside the centred rectangle |y − H/2| < a·H/2, |x − W/2| < a·W/2."""
    y, x = ray_grid(shape, oversample)
    return (np.abs(y - shape[0] / 2) < aperture * shape[0] / 2) & (np.abs(x - shape[1] / 2) < aperture * shape[1] / 2)


def ray_histogram(y: np.ndarray, x: np.ndarray, shape) -> np.ndarray:
    """Number of rays landing in each pixel (rays off the sensor are lost): (H, W) float64."""
    iy, ix = np.floor(y).astype(np.int64), np.floor(x).astype(np.int64)
    on = (iy >= 0) & (iy < shape[0]) & (ix >= 0) & (ix < shape[1])
    flat = np.bincount(iy[on] * shape[1] + ix[on], minlength=shape[0] * shape[1])
    return flat.reshape(shape).astype(np.float64)


def autocorrelation(psf: np.ndarray) -> np.ndarray:
    """Linear autocorrelation IFFT(|FFT(h)|²) on a 2H × 2W grid, peak (at [H, W]) scaled to 1."""
    padded_shape = (2 * psf.shape[0], 2 * psf.shape[1])
    power = np.abs(np.fft.rfft2(psf.astype(np.float64), s=padded_shape)) ** 2
    corr = np.fft.fftshift(np.fft.irfft2(power, s=padded_shape))
    return corr / corr.max()


def autocorrelation_halfwidth(psf: np.ndarray, level: float = 0.7, n_directions: int = 16,
                              step: float = 0.05) -> float:
    """Half-width (px) of the PSF autocorrelation's central lobe at ``level`` of its peak.

    The distance r at which the autocorrelation first falls below ``level`` along a ray
    from the peak (cubic-spline samples every ``step`` px out to min(H, W)/2, linear
    interpolation between the two straddling samples), averaged over ``n_directions``
    angles in [0, π) (the autocorrelation is point-symmetric). The paper's resolution
    measure (~3 px for its PSF).
    """
    reach = min(psf.shape) // 2
    corr = autocorrelation(psf)[psf.shape[0] - reach:psf.shape[0] + reach + 1, psf.shape[1] - reach:psf.shape[1] + reach + 1]
    coefficients = ndi.spline_filter(corr, order=3)
    radii = np.arange(0.0, reach, step)
    angles = np.linspace(0.0, np.pi, n_directions, endpoint=False)
    return float(np.mean([_first_crossing(coefficients, reach, angle, radii, level) for angle in angles]))


def _first_crossing(coefficients: np.ndarray, centre: int, angle: float, radii: np.ndarray, level: float) -> float:
    """The radius along ``angle`` from (centre, centre) where the spline-interpolated profile first drops below ``level``."""
    points = centre + radii[None, :] * np.array([[np.sin(angle)], [np.cos(angle)]])
    profile = ndi.map_coordinates(coefficients, points, order=3, prefilter=False)
    below = np.flatnonzero(profile < level)
    if below.size == 0:
        return float(radii[-1])
    i = below[0]
    return float(radii[i - 1] + (profile[i - 1] - level) / (profile[i - 1] - profile[i]) * (radii[i] - radii[i - 1]))


# ---- the spectral filter array ----------------------------------------------------------

def filter_transmissions(wavelengths_nm_grid, n_filters: int = N_FILTERS, lo: float = SPECTRAL_RANGE[0],
                         hi: float = SPECTRAL_RANGE[1], seed: int = 0) -> np.ndarray:
    """Filter transmissions T_f(λ) on a wavelength grid: (n_filters, len(grid)) float64.

    T_f(λ) = p_f · [line(c_f, w_f) + a_f·t_f · line(c_f − 150, 300) + b_f·(1 − t_f) · line(860, 40)]

    with centres c_f = band_wavelengths(n_filters, lo, hi), t_f = (c_f − c_0)/(c_last − c_0)
    (0 bluest, 1 reddest), FWHM w_f = 6 + 17·t_f nm and peak p_f ~ U(0.6, 0.95). The two
    small broad bumps are the side lobes of measured Fabry-Pérot SFAs: a blue shoulder of
    red/NIR filters (a_f ~ U(0.04, 0.06)) and a NIR leak of blue filters near 860 nm
    (b_f ~ U(0.03, 0.05)), both relative to the filter's peak. line = :func:`gaussian_line`.
    """
    lam = np.asarray(wavelengths_nm_grid, dtype=np.float64)[None, :]
    centres = band_wavelengths(n_filters, lo, hi)[:, None]
    t = (centres - centres[0]) / max(np.ptp(centres), 1e-12)
    rng = np.random.default_rng(seed)
    peak, shoulder, leak = (rng.uniform(*bounds, size=(n_filters, 1)) for bounds in ((0.6, 0.95), (0.04, 0.06), (0.03, 0.05)))
    fwhm = FWHM_RANGE[0] + (FWHM_RANGE[1] - FWHM_RANGE[0]) * t
    main = gaussian_line(centres, fwhm)(lam)
    blue_shoulder = shoulder * t * gaussian_line(centres - 150.0, 300.0)(lam)
    nir_leak = leak * (1.0 - t) * gaussian_line(860.0, 40.0)(lam)
    return peak * (main + blue_shoulder + nir_leak)


def filter_layout(seed: int = 0) -> np.ndarray:
    """Which filter sits at each position (r, c) of the TILE × TILE super-pixel: a seeded permutation."""
    return np.random.default_rng(seed).permutation(N_FILTERS).reshape(TILE, TILE)


def filter_coverage(shape, layout: np.ndarray, filter_px: float, misalignment, rotation_deg: float,
                    supersample: int = 4) -> np.ndarray:
    """Area fraction of each pixel under each filter: (N_FILTERS, H, W), summing to 1 per pixel.

    A sub-sample p of pixel (y, x) (pixel i covers [i, i+1)) maps to filter-array
    coordinates u = R(θ)(p − c) + c − m (c the frame centre, m the misalignment in px);
    it lies under the filter at tile position (⌊u_y/filter_px⌋ mod 8, ⌊u_x/filter_px⌋ mod 8).
    """
    ys, xs = ray_grid(shape, supersample)
    centre_y, centre_x = shape[0] / 2, shape[1] / 2
    theta = np.deg2rad(rotation_deg)
    uy = np.cos(theta) * (ys - centre_y) + np.sin(theta) * (xs - centre_x) + centre_y - misalignment[0]
    ux = -np.sin(theta) * (ys - centre_y) + np.cos(theta) * (xs - centre_x) + centre_x - misalignment[1]
    tile_index = layout[np.floor(uy / filter_px).astype(np.int64) % TILE, np.floor(ux / filter_px).astype(np.int64) % TILE]
    pixel = (np.arange(ys.shape[0])[:, None] // supersample) * shape[1] + np.arange(ys.shape[1])[None, :] // supersample
    counts = np.bincount((tile_index * shape[0] * shape[1] + pixel).ravel(), minlength=N_FILTERS * shape[0] * shape[1])
    return counts.reshape(N_FILTERS, shape[0], shape[1]) / supersample ** 2


def filter_array(shape, wavelengths, seed: int = 0, filter_px: float = 2.0, misalignment=(0.3, 0.45),
                 rotation_deg: float = 0.2) -> np.ndarray:
    """Per-pixel spectral response at the band wavelengths: (K, H, W) float32 in [0, 1].

    F_k(y, x) = Σ_f coverage_f(y, x) · T_f(λ_k): the 64 filters of :func:`filter_transmissions`
    (seeded), arranged by :func:`filter_layout` (seeded) in an 8×8 tile of
    ``filter_px``-pixel squares repeating every 8·filter_px px, shifted by ``misalignment``
    (dy, dx) px and rotated by ``rotation_deg`` about the frame centre, so pixels straddling
    filter edges blend their neighbours by area.
    """
    transmissions = filter_transmissions(np.asarray(wavelengths, dtype=np.float64), seed=seed)
    coverage = filter_coverage(shape, filter_layout(seed), filter_px, misalignment, rotation_deg)
    response = np.tensordot(transmissions.T, coverage, axes=1)
    return np.clip(response, 0.0, 1.0).astype(np.float32)


# ---- scenes -----------------------------------------------------------------------------

def border_px(shape) -> tuple[int, int]:
    """The zero border of a scene: max(1, round(5 % of each side))."""
    return tuple(max(1, round(BORDER_FRACTION * n)) for n in shape)


def inner_window(shape) -> tuple[slice, slice]:
    """The part of the sensor window inside the zero border."""
    by, bx = border_px(shape)
    return slice(by, shape[0] - by), slice(bx, shape[1] - bx)


def compose(masks: np.ndarray, spectra: np.ndarray) -> np.ndarray:
    """v_k(y, x) = Σ_r mask_r(y, x) · s_r(k): (R, H, W) spatial maps × (R, K) spectra -> (K, H, W)."""
    return np.einsum("rhw,rk->khw", masks, spectra)


def in_window(shape, inner_masks: np.ndarray) -> np.ndarray:
    """Masks drawn on the inner window (R, h, w), placed in zero frames (R, H, W)."""
    full = np.zeros((inner_masks.shape[0],) + tuple(shape))
    full[(slice(None),) + inner_window(shape)] = inner_masks
    return full


def inner_shape(shape) -> tuple[int, int]:
    """(h, w) of the inner window."""
    return tuple(s.stop - s.start for s in inner_window(shape))


def bar_triple(width: int) -> np.ndarray:
    """Three vertical bars of ``width`` px, ``width`` apart, 5·width tall: a (5w, 5w) 0/1 element."""
    element = np.zeros((5 * width, 5 * width))
    for start in (0, 2 * width, 4 * width):
        element[:, start:start + width] = 1.0
    return element


def bar_widths(box) -> list[int]:
    """The bar widths (1, 2, 3, 4, 6, 8, …, smallest first) whose rows fit in ``box``: 6·Σw ≤ h, 11·w ≤ w_box."""
    widths, height = [], 0
    for width in (1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64):
        if 6 * (height + width) > box[0] or 11 * width > box[1]:
            break
        widths.append(width)
        height += width
    return widths


def resolution_chart(box) -> np.ndarray:
    """A USAF-like chart in ``box``: rows of a vertical and a horizontal bar triple, widest at the top, centred."""
    widths = bar_widths(box)[::-1]
    chart = np.zeros(box)
    top = (box[0] - 6 * sum(widths) + min(widths, default=0)) // 2
    left = (box[1] - 11 * max(widths, default=0)) // 2
    for width in widths:
        element = bar_triple(width)
        chart[top:top + 5 * width, left:left + 5 * width] = element
        chart[top:top + 5 * width, left + 6 * width:left + 11 * width] = element.T
        top += 6 * width
    return chart


def quadrant_masks(box) -> np.ndarray:
    """Four resolution charts, one per quadrant of ``box`` (1-px gap between): (4, h, w), order TL, TR, BL, BR."""
    h, w = box
    quadrant = ((h - 1) // 2, (w - 1) // 2)
    masks = np.zeros((4,) + tuple(box))
    chart = resolution_chart(quadrant)
    for i, (oy, ox) in enumerate([(0, 0), (0, w - quadrant[1]), (h - quadrant[0], 0), (h - quadrant[0], w - quadrant[1])]):
        masks[i, oy:oy + quadrant[0], ox:ox + quadrant[1]] = chart
    return masks


def target_scene(shape, wavelengths, _rng: np.random.Generator) -> np.ndarray:
    """Resolution charts in four quadrants lit by red, green, blue (15 nm lines) and white (5000 K) light (not random)."""
    lights = [gaussian_line(RGB_LINES[name], LINE_FWHM) for name in ("red", "green", "blue")] + [blackbody(5000.0)]
    spectra = np.stack([band_average(light, wavelengths) for light in lights])
    return compose(in_window(shape, quadrant_masks(inner_shape(shape))), spectra)


def disc_masks(box, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """One 0/1 disc per (centre, radius): pixels whose centre is within the radius, (R, h, w)."""
    y, x = np.mgrid[0:box[0], 0:box[1]]
    distance2 = (y[None] - centres[:, 0, None, None]) ** 2 + (x[None] - centres[:, 1, None, None]) ** 2
    return (distance2 <= radii[:, None, None] ** 2).astype(np.float64)


def led_scene(shape, wavelengths, rng: np.random.Generator, grid=(4, 6)) -> np.ndarray:
    """A ``grid`` of LED spots (radius U(1, 2) px, brightness U(0.5, 1)) with three spectra: 460, 530, 630 nm lines."""
    box = inner_shape(shape)
    rows = np.linspace(0, box[0] - 1, grid[0] + 2)[1:-1]
    cols = np.linspace(0, box[1] - 1, grid[1] + 2)[1:-1]
    centres = np.round(np.stack(np.meshgrid(rows, cols, indexing="ij"), axis=-1).reshape(-1, 2))
    n_spots = len(centres)
    masks = disc_masks(box, centres, rng.uniform(1.0, 2.0, n_spots)) * rng.uniform(0.5, 1.0, (n_spots, 1, 1))
    colours = np.stack([band_average(gaussian_line(RGB_LINES[name], LED_FWHM), wavelengths) for name in ("blue", "green", "red")])
    assignment = rng.permutation(np.arange(n_spots) % 3)
    return compose(in_window(shape, masks), colours[assignment])


def smooth_random_spectrum(rng: np.random.Generator) -> Callable[[np.ndarray], np.ndarray]:
    """s(λ) = Σ_j a_j · line(c_j, w_j) over 2–3 broad Gaussians: a ~ U(0.2, 1), c ~ U(400, 880), w ~ U(60, 200) nm."""
    n = rng.integers(2, 4)
    amplitudes, centres, widths = rng.uniform(0.2, 1.0, n), rng.uniform(400.0, 880.0, n), rng.uniform(60.0, 200.0, n)
    return lambda lam: sum(a * gaussian_line(c, w)(lam) for a, c, w in zip(amplitudes, centres, widths))


def piecewise_scene(shape, wavelengths, rng: np.random.Generator, n_cells: int = 12) -> np.ndarray:
    """Voronoi cells around ``n_cells`` uniform random sites, each with its own smooth random spectrum."""
    box = inner_shape(shape)
    sites = rng.uniform((0, 0), box, size=(n_cells, 2))
    y, x = np.mgrid[0:box[0], 0:box[1]]
    nearest = np.argmin((y[None] - sites[:, 0, None, None]) ** 2 + (x[None] - sites[:, 1, None, None]) ** 2, axis=0)
    masks = (nearest[None] == np.arange(n_cells)[:, None, None]).astype(np.float64)
    spectra = np.stack([band_average(smooth_random_spectrum(rng), wavelengths) for _ in range(n_cells)])
    return compose(in_window(shape, masks), spectra)


def points_scene(shape, wavelengths, rng: np.random.Generator, separation: int = 4) -> np.ndarray:
    """Two single-pixel sources ``separation`` px apart in x near the centre (seeded jitter), one 530 nm line."""
    box = inner_shape(shape)
    jitter = rng.integers(-(np.array(box) // 8), np.array(box) // 8 + 1)
    y = int(np.clip(box[0] // 2 + jitter[0], 0, box[0] - 1))
    x0 = int(np.clip(box[1] // 2 - separation // 2 + jitter[1], 0, max(box[1] - 1 - separation, 0)))
    mask = np.zeros((1,) + box)
    mask[0, y, [x0, min(x0 + separation, box[1] - 1)]] = 1.0
    return compose(in_window(shape, mask), band_average(gaussian_line(RGB_LINES["green"], LINE_FWHM), wavelengths)[None])


def shared_data_dir() -> Path:
    """``$CLSDCAM_DATA`` when set, else ``../shared/data`` beside the repository."""
    return Path(os.environ.get("CLSDCAM_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


def envi_wavelengths(header: Path) -> np.ndarray:
    """The ``wavelength = { … }`` list of an ENVI header (nm)."""
    match = re.search(r"wavelength\s*=\s*\{([^}]*)\}", header.read_text())
    return np.array([float(v) for v in match.group(1).split(",")])


def read_samson(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """The Samson cube as (lines, samples, bands) float64 and its wavelengths (nm) from the ENVI header."""
    cube = np.fromfile(path, dtype="<i2").reshape(SAMSON_SHAPE).transpose(1, 2, 0).astype(np.float64)
    return cube, envi_wavelengths(path.with_name(path.name + ".hdr"))


def resample_spectra(cube: np.ndarray, source_nm: np.ndarray, wavelengths) -> np.ndarray:
    """Linear interpolation along the last axis, clamped: bands outside the source range take its end values."""
    query = np.clip(np.asarray(wavelengths, dtype=np.float64), source_nm[0], source_nm[-1])
    return interp1d(source_nm, cube, axis=-1)(query)


def central_crop(image: np.ndarray, aspect: float) -> np.ndarray:
    """The largest central crop of an (h, w, …) array with width/height = ``aspect``."""
    h, w = image.shape[:2]
    ch, cw = min(h, round(w / aspect)), min(w, round(h * aspect))
    top, left = (h - ch) // 2, (w - cw) // 2
    return image[top:top + ch, left:left + cw]


def realcube_scene(shape, wavelengths, _rng: np.random.Generator) -> np.ndarray:
    """The Samson airborne cube (400.9–899.1 nm): clamped-interpolated to the bands, centrally cropped to the
    window's aspect and zoomed (bilinear) onto the inner window; negative raw values clipped to 0 (not random)."""
    path = shared_data_dir() / SAMSON
    if not path.exists():
        raise InputError(f"scene 'realcube' needs ../shared/data/{SAMSON} (or $CLSDCAM_DATA/{SAMSON}); not present")
    raw, source_nm = read_samson(path)
    box = inner_shape(shape)
    cropped = central_crop(raw, box[1] / box[0])
    spectral = resample_spectra(cropped, source_nm, wavelengths).transpose(2, 0, 1)
    zoomed = ndi.zoom(spectral, (1.0, box[0] / spectral.shape[1], box[1] / spectral.shape[2]), order=1)
    cube = np.zeros((len(wavelengths),) + tuple(shape))
    cube[(slice(None),) + inner_window(shape)] = np.maximum(zoomed, 0.0)
    return cube


SCENE_BUILDERS = {
    "target": target_scene,
    "leds": led_scene,
    "piecewise": piecewise_scene,
    "points": points_scene,
    "realcube": realcube_scene,
}
SCENES = tuple(SCENE_BUILDERS)


def make_scene(name: str = "target", shape=DEFAULT_SHAPE, wavelengths=None, seed: int = 0) -> np.ndarray:
    """A scene cube (K, H, W) float32 ≥ 0 on the sensor window, zero in the border, peak 1.

    ``wavelengths`` defaults to :func:`band_wavelengths` (64 bands). See SCENES for the names.
    """
    if name not in SCENE_BUILDERS:
        raise InputError(f"--scene {name!r}: expected one of {', '.join(SCENES)}")
    wavelengths = band_wavelengths() if wavelengths is None else np.asarray(wavelengths, dtype=np.float64)
    cube = SCENE_BUILDERS[name](tuple(shape), wavelengths, np.random.default_rng(seed))
    if not cube.max() > 0:
        raise InputError(f"--scene {name!r}: the sensor {tuple(shape)} is too small to hold it")
    return (cube / cube.max()).astype(np.float32)


# ---- noise ------------------------------------------------------------------------------

def add_noise(b: np.ndarray, rng: np.random.Generator, gaussian_var: float = 0.0, photons: float | None = None) -> np.ndarray:
    """Shot noise, then read noise, in units of the measurement's peak m = max(b):

        b ← (m / N) · Poisson(N · max(b, 0) / m)   N = ``photons`` at the peak (None: no shot noise)
        b ← b + m · ε,  ε ~ 𝒩(0, gaussian_var)      (variance relative to m², i.e. of b/m; 0: none)

    An all-zero b is returned unchanged. The result may be negative (clip it if needed).
    """
    peak = float(np.max(b))
    noisy = np.asarray(b, dtype=np.float64)
    if peak <= 0.0:
        return noisy
    if photons is not None:
        noisy = rng.poisson(np.maximum(noisy, 0.0) / peak * photons) * (peak / photons)
    if gaussian_var > 0.0:
        noisy = noisy + rng.normal(0.0, np.sqrt(gaussian_var) * peak, noisy.shape)
    return noisy


# ---- the whole camera -------------------------------------------------------------------

@dataclass
class Simulation:
    calibration: Calibration    # psf (H, W), filters (K, H, W), wavelengths (K,)
    measurement: np.ndarray     # (H, W) float32 ≥ 0
    truth: np.ndarray           # (K, H, W) float32, the scene on the sensor window
    scene: str
    seed: int


def resolve_geometry(shape, n_bands, psf, filters) -> tuple[tuple[int, int], int]:
    """(H, W) and K from the arguments: given arrays win over the defaults; conflicts are InputErrors."""
    given_shape = psf.shape if psf is not None else (filters.shape[-2:] if filters is not None else None)
    if shape is not None and given_shape is not None and tuple(shape) != tuple(given_shape):
        raise InputError(f"shape {tuple(shape)} differs from the given psf/filters {tuple(given_shape)}")
    if n_bands is not None and filters is not None and n_bands != filters.shape[0]:
        raise InputError(f"n_bands {n_bands} differs from the given filters' {filters.shape[0]} bands")
    resolved_shape = tuple(given_shape or shape or DEFAULT_SHAPE)
    resolved_bands = filters.shape[0] if filters is not None else (n_bands or DEFAULT_BANDS)
    return resolved_shape, resolved_bands


def noiseless_measurement(psf: np.ndarray, filters: np.ndarray, cube: np.ndarray) -> np.ndarray:
    """b = Σ_k F_k ⊙ crop(h ∗ v_k) through :class:`ForwardModel` (float32 NumPy backend)."""
    model = ForwardModel(NumpyBackend("float32"), psf, filters)
    return model.backend.to_host(model.forward(model.embed(cube)))


def simulate(scene: str = "target", shape=None, n_bands: int | None = None, seed: int = 0,
             noise_var: float = 1e-5, photons: float | None = 20000.0,
             psf: np.ndarray | None = None, filters: np.ndarray | None = None) -> Simulation:
    """Simulate one Spectral DiffuserCam frame.

    shape (default 320 × 448) and n_bands (default 64) come from ``psf``/``filters`` when
    those are given. The PSF is :func:`caustic_psf`, the filters :func:`filter_array` at
    :func:`band_wavelengths`, all seeded by ``seed``. Noise (see :func:`add_noise`): shot
    noise at ``photons`` at the peak (default 20 000, a small pixel's full well), then
    Gaussian read noise of variance ``noise_var`` relative to the peak² (default 1e-5,
    σ ≈ 0.3 % of the peak); the measurement is clipped at 0.
    """
    shape, n_bands = resolve_geometry(shape, n_bands, psf, filters)
    wavelengths = band_wavelengths(n_bands)
    psf = caustic_psf(shape, seed) if psf is None else np.asarray(psf, dtype=np.float32)
    filters = filter_array(shape, wavelengths, seed) if filters is None else np.asarray(filters, dtype=np.float32)
    truth = make_scene(scene, shape, wavelengths, seed)
    clean = noiseless_measurement(psf, filters, truth)
    noisy = add_noise(clean, np.random.default_rng(seed), noise_var, photons)
    measurement = np.maximum(noisy, 0.0).astype(np.float32)
    calibration = Calibration(psf, filters, wavelengths, source=f"clsdcam.sim(scene={scene!r}, seed={seed})")
    return Simulation(calibration, measurement, truth, scene, seed)


def write_truth(path: Path, truth: np.ndarray, wavelengths: np.ndarray) -> None:
    """HDF5 with datasets ``cube`` (K, H, W) float32 and ``wavelengths`` (K,), written to a temp file then renamed."""
    temporary = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with h5py.File(temporary, "w") as f:
            f.create_dataset("cube", data=truth.astype(np.float32))
            f.create_dataset("wavelengths", data=np.asarray(wavelengths, dtype=np.float64))
        os.replace(temporary, path)
    finally:
        temporary.unlink(missing_ok=True)


def write_simulation(outdir, sim: Simulation) -> dict[str, Path]:
    """``calibration.h5``, ``measurement.npy`` and ``truth.h5`` in ``outdir`` (created); returns their paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = {name: outdir / name for name in ("calibration.h5", "measurement.npy", "truth.h5")}
    sim.calibration.save(paths["calibration.h5"])
    save_measurement(paths["measurement.npy"], sim.measurement)
    write_truth(paths["truth.h5"], sim.truth, sim.calibration.wavelengths)
    return {"calibration": paths["calibration.h5"], "measurement": paths["measurement.npy"], "truth": paths["truth.h5"]}


# ---- lens comparators (the paper's Fig. 7) ----------------------------------------------

SUPERPIXEL_PX = TILE * 2  # one 8×8 tile of 2-pixel filters


def lens_psf(shape=DEFAULT_SHAPE, spot_px: int = 2) -> np.ndarray:
    """A focused lens: a uniform ``spot_px`` × ``spot_px`` square at the frame centre (H//2, W//2)
    (top-left corner (H//2 − (spot_px−1)//2, …)), unit L2 norm, float32.

    spot_px = 2 (one filter pixel) is the paper's high-NA lens; 16 (one super-pixel) its low-NA lens.
    """
    psf = np.zeros(shape, np.float32)
    y0, x0 = shape[0] // 2 - (spot_px - 1) // 2, shape[1] // 2 - (spot_px - 1) // 2
    psf[y0:y0 + spot_px, x0:x0 + spot_px] = 1.0
    return psf / np.linalg.norm(psf)


DESIGNS = {  # name -> PSF builder (shape, seed)
    "diffuser": lambda shape, seed: caustic_psf(shape, seed),
    "low-NA lens": lambda shape, seed: lens_psf(shape, SUPERPIXEL_PX),
    "high-NA lens": lambda shape, seed: lens_psf(shape, 2),
}
