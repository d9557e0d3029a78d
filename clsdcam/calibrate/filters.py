"""``calibrate filters``: a monochromator sweep → the filter function F (K, H, W) of a calibration.

The sweep's transmission t_i (:mod:`.sweep`) is integrated into bands (:mod:`.bands`); defective pixels
(:mod:`.defects`) are set to 0 and F is scaled to max 1 over the rest. With a PSF calibration (``--psf``, from
``calibrate psf``) the result is a complete calibration: the PSF's raw steps are recorded for measurements, and
the PSF's centring shift is applied to F and the defect map so that pixel (y, x) of F, of the PSF frame and of
a measurement is the same sensor pixel. The sweep must then be cropped and binned as the PSF was (same size;
the same crop and bin when both come from frames of the same raw size).

Without ``--psf`` the file holds the filter part only (``filters`` (K, H, W), ``wavelength`` (K,),
``band_edges`` (K + 1,), ``dead_pixels`` (H, W)): no ``psf``, so it is not a calibration on its own.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, shape_text
from ..io import atomic_output, write_wavelengths
from .bands import band_centres, check_edges, integrate_bands
from .dark import resolve_dark
from .defects import Defects, find_defects
from .frames import open_sweep
from ..camera.raw import RawSteps, shift_image
from .sweep import exposure_weights, measure, power_weights, sweep_wavelengths


@dataclass(frozen=True, eq=False)
class FilterCalibration:
    filters: np.ndarray              # (K, h, w) float32, max 1, 0 at defects
    edges: np.ndarray                # (K + 1,) nm
    defects: Defects
    steps: RawSteps                  # the sweep's raw steps
    sweep_wavelengths: np.ndarray    # (N,) nm
    transmission: np.ndarray         # (N, h, w) t_i
    lines: tuple[str, ...]           # the report

    @property
    def wavelengths(self) -> np.ndarray:
        return band_centres(self.edges)


def calibrate_filters(sweep, wavelengths: str, edges: np.ndarray, power=None, exposure=None, dark=None,
                      dark_corner: int | None = None, crop=None, factor: int = 1,
                      saturation: float | None = None) -> FilterCalibration:
    """The filter function of the module docstring; every input is checked before the frames are read."""
    sweep = open_sweep(sweep)
    lam = sweep_wavelengths(wavelengths, sweep)
    weights = power_weights(power, lam) * exposure_weights(exposure, lam)
    check_edges(edges, lam)
    level, dark_frame, dark_text = resolve_dark(dark, dark_corner, sweep.frame(0))
    steps = RawSteps(sweep.shape, level, dark_frame, crop, factor)
    saturation = sweep.code_max if saturation is None else saturation
    measured = measure(sweep, steps, weights, saturation)
    defects = find_defects(measured.transmission, measured.peak_signal, measured.saturated, steps)
    integrals = np.where(defects.mask, 0.0, integrate_bands(lam, measured.transmission, edges))
    if not integrals.any():
        raise InputError(f"sweep {sweep.source}: every pixel is dead, hot or saturated")
    lines = (f"sweep {sweep.source}: {len(sweep)} frames {shape_text(sweep.shape)}, {lam[0]:g}–{lam[-1]:g} nm; "
             f"dark {dark_text}; {steps.geometry()} → {shape_text(integrals.shape[1:])}",
             f"bands: {edges.size - 1} over {edges[0]:g}–{edges[-1]:g} nm; filters scaled to max 1 "
             f"(largest band integral {integrals.max():.4g})",
             "defects: " + defects.describe() + ("" if saturation is None else f"; saturation at {saturation:g}"))
    return FilterCalibration((integrals / integrals.max()).astype(np.float32), edges, defects, steps, lam,
                             measured.transmission, lines)


def with_psf(result: FilterCalibration, psf_calibration, source: str):
    """A complete calibration: the PSF (and its raw steps) of ``psf_calibration`` with these filters, moved by
    the PSF's centring shift; InputError when the sizes or the spatial steps differ."""
    from ..camera.calibration import Calibration

    psf, raw = psf_calibration.psf, psf_calibration.raw
    if psf.shape != result.filters.shape[1:]:
        raise InputError(f"--psf {psf_calibration.source}: PSF {shape_text(psf.shape)}, filters "
                         f"{shape_text(result.filters.shape[1:])} (crop and bin the sweep as the PSF)")
    shift = (0, 0)
    if raw is not None:
        same_raw = tuple(raw.shape) == tuple(result.steps.shape)
        if same_raw and (raw.crop, raw.bin) != (result.steps.crop, result.steps.bin):
            raise InputError(f"--psf {psf_calibration.source}: PSF frames had {raw.geometry()}, the sweep "
                             f"{result.steps.geometry()} (same crop and bin needed)")
        shift = raw.shift
    filters = np.stack([shift_image(band, shift) for band in result.filters])
    dead = shift_image(result.defects.mask, shift)
    return Calibration(psf, filters, result.wavelengths, source=source, raw=raw, dead_pixels=dead)


def save_filters_only(path, result: FilterCalibration, source: str) -> Path:
    """The filter part of a calibration (module docstring), atomically."""
    import h5py

    path = Path(path)
    with atomic_output(path) as tmp, h5py.File(tmp, "w") as f:
        f["filters"] = result.filters
        write_wavelengths(f, result.wavelengths)
        f["band_edges"] = result.edges
        f["dead_pixels"] = result.defects.mask
        f.attrs["source"] = source
    return path

