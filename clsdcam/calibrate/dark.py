"""The dark: what the sensor reads without light, removed first (step 1 of :mod:`.raw`).

Three ways, from the command line's ``--dark`` and ``--dark-corner``:

- ``--dark FILE…``: the mean of dark frames of the frames' size, recorded as that mean frame;
- ``--dark LEVEL``: one number (a single value that parses as a number and names no file);
- ``--dark-corner N``: the mean of the N × N patch that starts N//2 pixels in from the top-left corner, rows
  and columns N//2 … N//2 + N − 1 (the outermost rows and columns, often unreliable, are skipped; N = 10 is
  the DiffuserCam tutorial's ``psf[5:15, 5:15]``), measured on the averaged PSF frame (or the first sweep
  frame) and recorded as a level: the sensor's offset, applied as is to later measurements.

Neither: no dark (level 0).
"""
from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np

from ..errors import InputError, shape_text
from .frames import average_frames

DARKS_KEPT = 2      # dark-frame sets kept per process: a batch's frames all use one


def corner_patch(n: int) -> tuple[slice, slice]:
    """Rows and columns N//2 … N//2 + N − 1."""
    return (slice(n // 2, n // 2 + n),) * 2


def corner_level(frame: np.ndarray, n: int) -> float:
    """Mean of :func:`corner_patch` (n) of ``frame``; InputError when the patch does not fit."""
    if n // 2 + n > min(frame.shape):
        raise InputError(f"--dark-corner {n}: the patch [{patch_text(n)}] does not fit in the "
                         f"{shape_text(frame.shape)} frame")
    return float(frame[corner_patch(n)].mean())


def patch_text(n: int) -> str:
    """'5:15, 5:15' for n = 10."""
    return f"{n // 2}:{n // 2 + n}, {n // 2}:{n // 2 + n}"


def dark_level(values) -> float | None:
    """``--dark``'s values as a level: one value that is a number and names no existing file; else None."""
    if len(values) != 1 or Path(values[0]).exists():
        return None
    try:
        return float(values[0])
    except ValueError:
        return None


def resolve_dark(values, corner: int | None, frame: np.ndarray) -> tuple[float, np.ndarray | None, str]:
    """(level, mean dark frame or None, description) from ``--dark`` values (or None), ``--dark-corner`` (or
    None) and the frame the corner is measured on."""
    if corner is not None:
        level = corner_level(frame, corner)
        return level, None, f"{level:.6g} (corner patch [{patch_text(corner)}])"
    if not values:
        return 0.0, None, "none"
    level = dark_level(values)
    if level is not None:
        return level, None, f"{level:.6g}"
    dark = mean_dark(values)
    if dark.shape != frame.shape:
        raise InputError(f"dark {values[0]}: {shape_text(dark.shape)}, but the frames are {shape_text(frame.shape)}")
    return 0.0, dark, f"mean of {len(values)} dark frame{'s' * (len(values) > 1)} (mean {dark.mean():.6g})"


def mean_dark(values) -> np.ndarray:
    """The mean of the dark frame files ``values`` (read-only), read once per process while the files are
    unchanged (same paths, sizes and modification times): a batch subtracts it from every frame."""
    return _mean_of(tuple((str(v), *_stamp(v)) for v in values))


def _stamp(path) -> tuple[int, int]:
    """(modification time in ns, size) of a file; (0, 0) when it cannot be read (the reader says why)."""
    try:
        stat = os.stat(path)
    except OSError:
        return 0, 0
    return stat.st_mtime_ns, stat.st_size


@functools.lru_cache(maxsize=DARKS_KEPT)
def _mean_of(files: tuple[tuple[str, int, int], ...]) -> np.ndarray:
    dark, _ = average_frames([name for name, _, _ in files], "dark")
    dark.setflags(write=False)
    return dark
