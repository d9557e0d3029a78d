"""The caustic PSF of a smooth random diffuser, and its autocorrelation (the resolution measure).

The diffuser surface g is white noise smoothed by a Gaussian; a ray through point p is
deflected to p + c·∇g(p), and the PSF h is the density of the landing points (blurred by
the pixel and diffraction), normalised to ‖h‖₂ = 1. Caustic folds form where an eigenvalue
of I + c·Hess g crosses 0. The resolution is the half-width of the central lobe of the
autocorrelation h ⋆ h = IFFT(|FFT(h)|²) at 70 % of its peak (about 3 px, the paper's).
"""
from __future__ import annotations

import numpy as np
import scipy.ndimage as ndi

from .sensor import DEFAULT_SHAPE, ray_grid

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
