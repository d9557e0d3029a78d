"""The raw steps: what turns a raw sensor frame into a frame of the calibration's size, recorded in the
calibration so that a raw measurement is turned the same way (:func:`apply_raw_steps`).

In order, on a frame of the raw shape (H, W):

1. dark: b ← max(b − d, 0), d a level (a number) or the mean dark frame (H, W);
2. crop: the window rows y0:y1, columns x0:x1 (half-open, raw pixel coordinates);
3. bin: means over n × n blocks, the ragged edge (rows and columns beyond a multiple of n) dropped;
4. shift: b'(p) = b(p − s), s = (dy, dx) whole pixels of the binned frame, zero fill (the PSF's
   centring, so the same pixel of a measurement meets the same pixel of the PSF).

HDF5 layout (group ``raw`` of a calibration file; absent = no raw steps known):
attributes ``shape`` (2,) int, the raw frame; ``crop`` (4,) int y0, y1, x0, x1 (absent = none);
``bin`` int (1 = none); ``shift`` (2,) int dy, dx; ``dark_level`` float when the dark is a level
(``--dark LEVEL`` or ``--dark-corner N``, the level measured on the PSF frame); dataset ``raw/dark``
(H, W) float32 when the dark is the mean of dark frames (``--dark FILE…``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, shape_text

GROUP = "raw"


@dataclass(frozen=True, eq=False)
class RawSteps:
    """The raw frame's shape and the steps of the module docstring, in their order."""

    shape: tuple[int, int]
    dark_level: float = 0.0
    dark_frame: np.ndarray | None = None     # (H, W): subtracted instead of dark_level
    crop: tuple[int, int, int, int] | None = None
    bin: int = 1
    shift: tuple[int, int] = (0, 0)

    def describe(self) -> str:
        """One line: 'raw 1200×1600: dark 34.08, crop none, bin 4×4, shift (0, 0)'."""
        dark = "mean dark frame" if self.dark_frame is not None else f"{self.dark_level:.6g}"
        return f"raw {shape_text(self.shape)}: dark {dark}, {self.geometry()}"

    def geometry(self) -> str:
        """The spatial steps: 'crop none, bin 4×4, shift (0, 0)'."""
        crop = "none" if self.crop is None else "{}:{},{}:{}".format(*self.crop)
        return f"crop {crop}, bin {self.bin}×{self.bin}, shift ({self.shift[0]}, {self.shift[1]})"


def subtract_dark(frame: np.ndarray, steps: RawSteps) -> np.ndarray:
    """max(b − d, 0) with d the dark frame, else the dark level."""
    dark = steps.dark_frame if steps.dark_frame is not None else steps.dark_level
    return np.maximum(np.asarray(frame, np.float64) - dark, 0.0)


def crop_frame(frame: np.ndarray, crop) -> np.ndarray:
    """frame[y0:y1, x0:x1], or InputError when the window does not lie inside the frame."""
    if crop is None:
        return frame
    y0, y1, x0, x1 = crop
    if y1 > frame.shape[0] or x1 > frame.shape[1]:
        raise InputError(f"--crop {y0}:{y1},{x0}:{x1} lies outside the {shape_text(frame.shape)} frame")
    return frame[y0:y1, x0:x1]


def bin_pixels(image: np.ndarray, factor: int) -> np.ndarray:
    """Mean over f × f blocks (the ragged edge dropped), as a sensor binning its pixels."""
    h, w = (n // factor * factor for n in image.shape)
    if h == 0 or w == 0:
        raise InputError(f"--bin {factor}: larger than the {shape_text(image.shape)} frame")
    return image[:h, :w].reshape(h // factor, factor, w // factor, factor).mean(axis=(1, 3))


def shift_image(image: np.ndarray, shift) -> np.ndarray:
    """out(p) = image(p − s) for s = (dy, dx) whole pixels; zero where p − s falls off the image."""
    (dy, dx), (h, w) = shift, image.shape
    out = np.zeros_like(image)
    out[max(dy, 0):h + min(dy, 0), max(dx, 0):w + min(dx, 0)] = \
        image[max(-dy, 0):h - max(dy, 0), max(-dx, 0):w - max(dx, 0)]
    return out


def apply_raw_steps(steps: RawSteps, frame: np.ndarray) -> np.ndarray:
    """A raw frame of ``steps.shape`` turned into the calibration's size: dark, crop, bin, shift."""
    frame = np.asarray(frame, np.float64)
    if frame.shape != tuple(steps.shape):
        raise InputError(f"frame {shape_text(frame.shape)} is not of the recorded raw size {shape_text(steps.shape)}")
    binned = bin_pixels(crop_frame(subtract_dark(frame, steps), steps.crop), steps.bin)
    return shift_image(binned, steps.shift) if any(steps.shift) else binned


def write_record(f, steps: RawSteps) -> None:
    """Group ``raw`` of an open HDF5 file (the layout of the module docstring)."""
    group = f.create_group(GROUP)
    group.attrs.update(shape=np.asarray(steps.shape, np.int64), bin=int(steps.bin),
                       shift=np.asarray(steps.shift, np.int64))
    if steps.crop is not None:
        group.attrs["crop"] = np.asarray(steps.crop, np.int64)
    if steps.dark_frame is not None:
        group["dark"] = np.asarray(steps.dark_frame, np.float32)
    else:
        group.attrs["dark_level"] = float(steps.dark_level)


def read_record(f, name: str) -> RawSteps | None:
    """The raw steps of an open HDF5 file, None when it records none; InputError (prefixed ``name``) when the
    group is incomplete."""
    if GROUP not in f:
        return None
    group = f[GROUP]
    try:
        crop = tuple(int(v) for v in group.attrs["crop"]) if "crop" in group.attrs else None
        steps = RawSteps(shape=tuple(int(v) for v in group.attrs["shape"]),
                         dark_level=float(group.attrs.get("dark_level", 0.0)),
                         dark_frame=group["dark"][...].astype(np.float64) if "dark" in group else None,
                         crop=crop, bin=int(group.attrs["bin"]), shift=tuple(int(v) for v in group.attrs["shift"]))
    except (KeyError, ValueError, TypeError) as exc:
        raise InputError(f"{name}: group 'raw' is incomplete ({exc})") from None
    if steps.dark_frame is not None and steps.dark_frame.shape != steps.shape:
        raise InputError(f"{name}: raw/dark {shape_text(steps.dark_frame.shape)} is not the raw size "
                         f"{shape_text(steps.shape)}")
    return steps
