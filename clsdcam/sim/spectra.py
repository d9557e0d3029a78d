"""Spectral sampling: the band wavelengths, their bins, band averages, and analytic spectra.

K bands split the calibrated range [lo, hi] into equal bins; band k is centred at
λ_k = lo + (k + ½)(hi − lo)/K. Analytic spectra s(λ) are sampled as band averages
s_k = (1/|B_k|) ∫_{B_k} s(λ) dλ over each bin B_k, so narrow lines keep their energy at
any band count. The spectra: a Gaussian line and Planck's black body.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import InputError
from ..camera.prototype import N_BANDS as DEFAULT_BANDS
from ..camera.prototype import SPECTRAL_RANGE


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
