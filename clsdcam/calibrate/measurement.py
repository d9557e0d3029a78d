"""A measurement's own raw steps: frames averaged, a dark removed, pixels binned (``clsdcam reconstruct
MEASUREMENT… --average N --dark FILE…|LEVEL --bin N``; in Python :func:`clsdcam.calibration.prepare` with a list of
files and ``Preprocessing(dark=…, bin=…)``): the same path for both.

1. frames: b = (1/n) Σ_i frame_i over the n files given (``--average N``: the first N);
2. then the steps of :mod:`.raw` on b:

   - b of the calibration's recorded raw size (``Calibration.raw``): the recorded steps (dark, crop, bin,
     shift), the measurement's own dark d in place of the recorded one when one is given; ``--bin`` may only
     repeat the recorded bin (the calibration's size is fixed by it);
   - any other b: b ← max(b − d, 0), then n × n block means (no crop, no shift).

The dark d is a level, or the mean of dark frames of b's size (:func:`.dark.resolve_dark`).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from ..errors import InputError, shape_text
from .dark import resolve_dark
from .frames import average_frames
from .raw import RawSteps


def mean_frame(measurement) -> tuple[np.ndarray, list[str]]:
    """(frame, notes): a path is read, a list of several paths averaged ((1/n) Σ frame_i, noted), an array taken
    as it is."""
    from ..io import load_measurement

    if isinstance(measurement, (list, tuple)) and len(measurement) > 1:
        return average_frames(measurement, "measurement"), [f"measurement: mean of {len(measurement)} frames"]
    if isinstance(measurement, (list, tuple)):
        measurement = measurement[0]
    if isinstance(measurement, (str, Path)):
        return load_measurement(measurement), []
    return np.asarray(measurement, np.float64), []


def measurement_dark(dark, frame: np.ndarray) -> tuple[float, np.ndarray | None]:
    """(level, mean dark frame or None) from ``dark``: None (0), a level, or dark frame files (averaged; InputError
    unless of ``frame``'s size)."""
    if dark is None or isinstance(dark, (int, float)):
        return float(dark or 0.0), None
    return resolve_dark(list(dark), None, frame)[:2]


def measurement_steps(raw: RawSteps | None, frame: np.ndarray, dark=None, bin: int = 1) -> tuple[RawSteps | None, str]:
    """(steps, label) for a measurement frame, as in the module docstring; (None, "") when there is nothing to do."""
    recorded = raw is not None and frame.shape == tuple(raw.shape)
    if recorded and bin not in (1, raw.bin):
        raise InputError(f"--bin {bin}: the measurement has the calibration's raw size {shape_text(raw.shape)}, "
                         f"whose recorded steps bin it {raw.bin}×{raw.bin}; leave out --bin")
    if not recorded and dark is None and bin == 1:
        return None, ""
    level, dark_frame = measurement_dark(dark, frame)
    if not recorded:
        return RawSteps(frame.shape, level, dark_frame, bin=bin), "steps applied to the measurement"
    if dark is None:
        return raw, "raw steps applied to the measurement"
    return replace(raw, dark_level=level, dark_frame=dark_frame), "raw steps applied to the measurement, its own dark"
