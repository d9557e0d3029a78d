"""Pictures of a calibration in the making (``--png PREFIX``), through :mod:`clsdcam.render`'s figure helpers
(their own Agg canvas, PNGs written atomically).

- ``calibrate psf``: PREFIX_psf.png (the PSF, display white at its 99.9th percentile) and
  PREFIX_autocorrelation.png (h ⋆ h around its peak with the 70 % contour, :func:`clsdcam.sim.autocorrelation`);
- ``calibrate filters``: PREFIX_peak_wavelength.png (argmax_λ t(λ; y, x) per pixel, defects blank) and
  PREFIX_transmission.png (t(λ) / max t of CURVES pixels whose peak wavelengths spread evenly over the map's).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..render import new_figure, save_figure, save_autocorrelation, save_curves

CURVES = 6


def picture_paths(prefix, names) -> list[Path]:
    prefix = Path(prefix)
    return [prefix.with_name(f"{prefix.name}_{name}.png") for name in names]


def save_psf_pictures(prefix, psf: np.ndarray) -> list[Path]:
    from ..sim import autocorrelation, autocorrelation_halfwidth

    image_path, corr_path = picture_paths(prefix, ("psf", "autocorrelation"))
    fig = new_figure(figsize=(6, 4.8))
    ax = fig.subplots()
    shown = ax.imshow(psf, cmap="magma", vmax=np.percentile(psf, 99.9) or None, interpolation="nearest")
    ax.plot(psf.shape[1] // 2, psf.shape[0] // 2, "+", color="cyan", ms=12)
    ax.set(title=f"PSF {psf.shape[0]}×{psf.shape[1]} (+: centre, the PSF origin)", xlabel="x (px)", ylabel="y (px)")
    fig.colorbar(shown, ax=ax)
    return [save_figure(fig, image_path),
            save_autocorrelation(corr_path, autocorrelation(psf), autocorrelation_halfwidth(psf))]


def save_filter_pictures(prefix, wavelengths: np.ndarray, transmission: np.ndarray, defects: np.ndarray) -> list[Path]:
    """The two filter pictures from t (N, H, W) at ``wavelengths`` (N,) and the defect map (H, W)."""
    map_path, curves_path = picture_paths(prefix, ("peak_wavelength", "transmission"))
    peak = np.where(defects, np.nan, wavelengths[np.argmax(transmission, axis=0)])
    fig = new_figure(figsize=(6.5, 4.8))
    ax = fig.subplots()
    shown = ax.imshow(peak, cmap="turbo", interpolation="nearest")
    ax.set(title="peak wavelength of each pixel (nm; defects blank)", xlabel="x (px)", ylabel="y (px)")
    fig.colorbar(shown, ax=ax)
    top = transmission[:, ~defects].max() if not defects.all() else 1.0
    curves = {f"(y={y}, x={x})": (wavelengths, transmission[:, y, x] / top) for y, x in spread_pixels(peak, CURVES)}
    return [save_figure(fig, map_path),
            save_curves(curves_path, "transmission of a few filter pixels", "wavelength (nm)",
                        "t(λ) / max t (defects left out)", curves)]


def spread_pixels(peak: np.ndarray, n: int) -> list[tuple[int, int]]:
    """n pixels at the (i + ½)/n quantiles of the peak-wavelength map (defects, NaN, left out)."""
    valid = np.flatnonzero(np.isfinite(peak.ravel()))
    order = valid[np.argsort(peak.ravel()[valid], kind="stable")]
    picks = order[((np.arange(n) + 0.5) / n * order.size).astype(int)] if order.size else []
    return [tuple(int(v) for v in np.unravel_index(i, peak.shape)) for i in picks]
