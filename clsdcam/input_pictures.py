"""The picture of what a cube was reconstructed from (``PREFIX_input.png``): the raw frame, the PSF and, for a
spectral calibration, the filter array's layout, drawn with :mod:`clsdcam.render`'s figure helpers."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .render import new_figure, save_figure

PSF_TICKS = (0.0, 0.05, 0.2, 0.5, 1.0)   # fractions of the PSF's peak, nearly evenly spaced on its √ colour bar
FILTER_CROP = 32    # px: the filter-layout panel shows this square at the sensor's centre (2×2 tiles of the prototype)


@dataclass
class Inputs:
    """What a cube was reconstructed from; a part that is not known is None."""

    frame: np.ndarray | None = None          # the raw frame b (H, W), as recorded
    frame_source: str = ""
    psf: np.ndarray | None = None            # the calibration's PSF h (H, W)
    filters: np.ndarray | None = None        # its filter function F (K, H, W)
    wavelengths: np.ndarray | None = None    # its band wavelengths (K,), nm
    calibration_source: str = ""

    @classmethod
    def of(cls, frame=None, frame_source: str = "", calibration=None, calibration_source: str = "") -> "Inputs":
        """From a frame and a :class:`clsdcam.camera.calibration.Calibration` (either may be None)."""
        if calibration is None:
            return cls(frame, frame_source)
        return cls(frame, frame_source, calibration.psf, calibration.filters, calibration.wavelengths,
                   calibration_source)

    def __bool__(self) -> bool:
        return self.frame is not None or self.psf is not None


def save_input_picture(prefix, inputs: Inputs) -> list[Path]:
    """[``{prefix}_input.png``] (:func:`input_figure`), or [] (nothing written) when ``inputs`` holds neither a
    frame nor a PSF."""
    if not inputs:
        return []
    prefix = Path(prefix)
    return [save_figure(input_figure(inputs), prefix.with_name(f"{prefix.name}_input.png"))]


def input_figure(inputs: Inputs):
    """One panel per known part: the raw frame b (grey, linear, with its colour bar in the frame's units), the PSF
    h (grey, as a fraction of its peak on a √ scale, so that its faint caustics show) and, for a spectral
    calibration (K > 1), the filter array's layout: the wavelength of each pixel's most transmitted band,
    λ[argmax_k F_k(y, x)], on a FILTER_CROP-pixel square at the sensor's centre."""
    spectral = inputs.filters is not None and len(inputs.filters) > 1
    panels = [draw for draw, known in ((_frame_panel, inputs.frame is not None), (_psf_panel, inputs.psf is not None),
                                       (_filter_panel, spectral)) if known]
    fig = new_figure(figsize=(5 * len(panels), 4.6), layout="compressed")
    for ax, draw in zip(fig.subplots(1, len(panels), squeeze=False)[0], panels):
        draw(fig, ax, inputs)
        ax.set(xlabel="x (px)", ylabel="y (px)")
    return fig


def _frame_panel(fig, ax, inputs: Inputs):
    fig.colorbar(ax.imshow(inputs.frame, cmap="gray", interpolation="nearest"), ax=ax, shrink=0.8,
                 label="raw value (measurement units)")
    ax.set_title(f"raw frame b\n{inputs.frame_source}", fontsize="medium")


def _psf_panel(fig, ax, inputs: Inputs):
    from matplotlib.colors import PowerNorm

    psf = np.clip(inputs.psf, 0, None)
    image = ax.imshow(psf / (psf.max() or 1.0), cmap="gray", norm=PowerNorm(0.5, vmin=0.0, vmax=1.0))
    fig.colorbar(image, ax=ax, shrink=0.8, ticks=PSF_TICKS, label="intensity (fraction of its peak, √ scale)")
    ax.set_title(f"PSF h (√ scale)\n{inputs.calibration_source}", fontsize="medium")


def _filter_panel(fig, ax, inputs: Inputs):
    """λ[argmax_k F_k] on the central FILTER_CROP × FILTER_CROP pixels, in sensor coordinates, with a colour bar."""
    filters, wavelengths = inputs.filters, np.asarray(inputs.wavelengths, np.float64)
    _, h, w = filters.shape
    y0, x0 = max(0, (h - FILTER_CROP) // 2), max(0, (w - FILTER_CROP) // 2)
    crop = filters[:, y0:y0 + FILTER_CROP, x0:x0 + FILTER_CROP]
    extent = (x0 - 0.5, x0 + crop.shape[2] - 0.5, y0 + crop.shape[1] - 0.5, y0 - 0.5)
    image = ax.imshow(wavelengths[np.argmax(crop, axis=0)], cmap="turbo", extent=extent, vmin=wavelengths.min(),
                      vmax=wavelengths.max(), interpolation="nearest")
    fig.colorbar(image, ax=ax, shrink=0.8, label="most transmitted band (nm)")
    ax.set_title(f"filter array: each pixel's band\n(central {crop.shape[1]}×{crop.shape[2]} px)", fontsize="medium")
