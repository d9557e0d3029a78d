"""``calibrate psf``: photos of a point source → the PSF of a calibration.

h = the mean of the frames, then the raw steps of :mod:`.raw` (dark, clipped at 0; crop; n × n bin), then, with
``center``, the shift s = round(c − m) that moves the centroid m = Σ_p p·h(p) / Σ_p h(p) onto the frame centre
c = (H//2, W//2) (the PSF origin of docs/conventions.md; whole pixels, zero fill), and finally h / ‖h‖₂.
The report gives the brightest pixel and the centroid against c, and the support of the normalised PSF
(:func:`clsdcam.camera.geometry.psf_support`: the box holding all but 1e-4 of its L1 mass, as offsets from c).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, shape_text
from ..camera.geometry import psf_centre, psf_support
from .dark import resolve_dark
from .frames import average_frames
from ..camera.raw import RawSteps, apply_raw_steps, shift_image

@dataclass(frozen=True, eq=False)
class PsfCalibration:
    psf: np.ndarray                   # (H, W), unit L2 norm
    steps: RawSteps                   # what was done to the raw frames
    frames: int
    dark: str                         # how the dark was found
    peak: tuple[int, int]             # brightest pixel, before centring
    centroid: tuple[float, float]     # before centring


def calibrate_psf(paths, dark=None, dark_corner: int | None = None, crop=None, factor: int = 1,
                  center: bool = False) -> PsfCalibration:
    """The PSF of the module docstring from frame files; ``dark``: ``--dark``'s values (or None)."""
    raw, _ = average_frames(paths, "psf frame")
    level, dark_frame, dark_text = resolve_dark(dark, dark_corner, raw)
    steps = RawSteps(raw.shape, level, dark_frame, crop, factor)
    image = apply_raw_steps(steps, raw)
    if not image.any():
        raise InputError(f"psf {paths[0]}: nothing above the dark level ({dark_text})")
    peak = tuple(int(i) for i in np.unravel_index(np.argmax(image), image.shape))
    centroid = tuple(float(c) for c in centroid_of(image))
    if center:
        shift = tuple(int(round(c - m)) for c, m in zip(psf_centre(image.shape), centroid))
        steps, image = replace(steps, shift=shift), shift_image(image, shift)
    return PsfCalibration(image / np.linalg.norm(image), steps, len(paths), dark_text, peak, centroid)


def centroid_of(image: np.ndarray) -> np.ndarray:
    """(Σ_p y·h(p), Σ_p x·h(p)) / Σ_p h(p)."""
    ys, xs = np.indices(image.shape)
    return np.array([(ys * image).sum(), (xs * image).sum()]) / image.sum()


def report_lines(result: PsfCalibration) -> list[str]:
    """What was done and where the PSF sits: steps, centring, support."""
    steps, (h, w) = result.steps, result.psf.shape
    c = psf_centre(result.psf.shape)
    (ry, rx) = psf_support(result.psf)
    offset = tuple(m - ci for m, ci in zip(result.centroid, c))
    return [f"psf: {result.frames} frame{'s' * (result.frames > 1)} {shape_text(steps.shape)} averaged; "
             f"dark {result.dark}; {steps.geometry()} → {shape_text((h, w))}",
             f"centring: peak at ({result.peak[0]}, {result.peak[1]}), centroid at ({result.centroid[0]:.1f}, "
             f"{result.centroid[1]:.1f}), frame centre ({c[0]}, {c[1]}): centroid off by "
             f"({offset[0]:+.1f}, {offset[1]:+.1f}) px" +
             (f"; moved by ({steps.shift[0]:+d}, {steps.shift[1]:+d}) px" if any(steps.shift) else
              ("" if max(map(abs, offset)) < 1 else " (--center moves it there)")),
             f"support: rows {ry[0]:+d}…{ry[1]:+d}, columns {rx[0]:+d}…{rx[1]:+d} px from the centre "
             f"({ry[1] - ry[0] + 1}×{rx[1] - rx[0] + 1} of {h}×{w})"]


def one_band(result: PsfCalibration, wavelength: float, source: str):
    """A complete one-band calibration (plain DiffuserCam: filters all ones (1, H, W)) with the raw steps."""
    from ..camera.calibration import Calibration

    return Calibration(result.psf, np.ones((1,) + result.psf.shape), [wavelength], source=source, raw=result.steps)
