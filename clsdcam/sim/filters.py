"""The spectral filter array: 64 narrow-band filters in an 8×8 tile repeated over the sensor.

Each filter f has a transmission T_f(λ) (a Gaussian pass band plus the two small side lobes
of measured Fabry-Pérot filters); each pixel (y, x) is covered by the filters in area
fractions coverage_f(y, x) (the array may be shifted and rotated against the pixels), so the
per-pixel response at band k is

    F_k(y, x) = Σ_f coverage_f(y, x) · T_f(λ_k),

sampled at the band wavelengths. Every random choice is seeded.
"""
from __future__ import annotations

import numpy as np

from .sensor import ray_grid
from .spectra import SPECTRAL_RANGE, band_wavelengths, gaussian_line

N_FILTERS = 64
TILE = 8                           # the filter array is a TILE × TILE super-pixel
FWHM_RANGE = (6.0, 23.0)           # nm, filter FWHM from the bluest to the reddest filter

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
