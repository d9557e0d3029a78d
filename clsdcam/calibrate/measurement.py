"""A measurement's own raw steps: frames averaged, a dark removed, pixels binned (``clsdcam reconstruct
MEASUREMENT… --average N --dark FILE…|LEVEL --bin N``; in Python :func:`prepare` (``clsdcam.prepare``) with a list
of files and ``Preprocessing(dark=…, bin=…)``): the same path for both, which ends in the calibration's
preprocessing (:func:`clsdcam.camera.calibration.preprocess`).

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

from ..camera.calibration import Calibration, Preprocessing, preprocess
from ..errors import InputError, shape_text
from ..camera.raw import RawSteps, apply_raw_steps
from .dark import resolve_dark
from .frames import average_frames

PLATEAU = 1e-3           # more than this fraction of the pixels at the frame's maximum: a clipped plateau
MOSTLY_SATURATED = 0.5   # more than this fraction saturated: refused


def mean_frame(measurement) -> tuple[np.ndarray, float | None, list[str]]:
    """(frame, code, notes): a path is read, a list of several paths averaged ((1/n) Σ frame_i, noted), an array
    taken as it is; code is the saturation code of the stored integer type (:func:`clsdcam.io.code_max`)."""
    from ..io import code_max, load_frame

    if isinstance(measurement, (list, tuple)) and len(measurement) > 1:
        return *average_frames(measurement, "measurement"), [f"measurement: mean of {len(measurement)} frames"]
    if isinstance(measurement, (list, tuple)):
        measurement = measurement[0]
    if isinstance(measurement, (str, Path)):
        return *load_frame(measurement), []
    array = np.asarray(measurement)
    return array.astype(np.float64), code_max(array.dtype), []


def frame_name(measurement) -> str:
    """How messages name a measurement: ``measurement FILE`` (the first file when several are averaged), or
    ``measurement`` for an array."""
    first = measurement[0] if isinstance(measurement, (list, tuple)) and measurement else measurement
    return f"measurement {first}" if isinstance(first, (str, Path)) else "measurement"


def check_signal(frame: np.ndarray, name: str) -> None:
    """InputError for a frame with nothing to reconstruct: every pixel 0 (an all-zero frame, or nothing above the
    dark), or every pixel one value."""
    top = float(frame.max())
    if frame.min() == top:
        kind = "an all-zero frame" if top == 0 else "a constant frame"
        raise InputError(f"{name}: every pixel is {top:g} ({kind}): nothing to reconstruct")


def saturation_level(frame: np.ndarray, reached_code: bool) -> float | None:
    """The level of ``Preprocessing(saturation="auto")``: the frame's maximum when the raw frame reached its
    integer type's largest value (``reached_code``), or when more than one pixel and more than PLATEAU of them
    share it (a flat top is clipped light; a peak of a linear image is a point); else None (nothing saturated)."""
    top = float(frame.max())
    return top if reached_code or np.sum(frame == top) > max(1.0, PLATEAU * frame.size) else None


def saturation_notes(frame: np.ndarray, level: float | None, name: str) -> list[str]:
    """The line that says which fraction of ``frame`` is at or above the saturation ``level`` (excluded from the
    data term by :func:`clsdcam.camera.calibration.preprocess`), none when no pixel is; InputError when more than
    MOSTLY_SATURATED of the pixels are."""
    fraction = 0.0 if level is None else float(np.mean(frame >= level))
    if fraction > MOSTLY_SATURATED:
        raise InputError(f"{name}: {100 * fraction:.0f}% of the pixels are saturated (≥ {level:g}): too little "
                         "light is measured linearly to reconstruct (shorten the exposure; --saturation none keeps "
                         "them)")
    return [f"saturation: {100 * fraction:.2g}% of the pixels (≥ {level:g}) excluded from the data term"] \
        if fraction else []


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


def prepare(measurement, calibration, options: "Preprocessing | None" = None, report=None):
    """(calibration, measurement) ready to solve, the same way for the API and the command line. ``measurement``:
    a file path, a list of file paths (their mean) or an array; ``calibration``: a :class:`Calibration` or a file
    path. Then the measurement's raw steps (:func:`raw_steps`) and :func:`preprocess` with ``options`` (default:
    :class:`Preprocessing` ()). The calibration's ``scale`` brings solved cubes back to its units. A frame with
    nothing to reconstruct (all zero, or constant) is an InputError (:func:`check_signal`), and so is one mostly
    saturated (:func:`saturation_notes`); ``saturation="auto"`` becomes :func:`saturation_level`'s level.

    What was done to the measurement (frames averaged, raw steps, saturated pixels excluded) is appended to the
    returned calibration's ``source`` ("…; raw steps applied to the measurement: …"), and with it to the
    ``calibration`` attribute of a cube solved on it; ``report`` (if given) is called with each of those lines."""
    options = options or Preprocessing()
    if not isinstance(calibration, Calibration):
        calibration = Calibration.load(calibration)
    name = frame_name(measurement)
    measurement, code, averaged = mean_frame(measurement)
    reached_code = code is not None and measurement.max() >= code
    measurement, steps = raw_steps(calibration, measurement, options)
    check_signal(measurement, name + " after its raw steps" * bool(steps))
    if options.saturation == "auto":
        options = replace(options, saturation=saturation_level(measurement, reached_code))
    notes = averaged + steps + saturation_notes(measurement, options.saturation, name)
    for line in notes if report else ():
        report(line)
    source = "; ".join([calibration.source, *notes])
    return preprocess(replace(calibration, source=source), measurement, options)


def raw_steps(calibration: Calibration, measurement, options: Preprocessing) -> tuple[np.ndarray, list[str]]:
    """(measurement, notes) after the measurement's raw steps (the module docstring): the
    calibration's recorded ones (``calibration.raw``) when the measurement has the recorded raw size, with
    ``options.dark`` in place of the recorded dark when given; else ``options.dark`` and ``options.bin``."""
    measurement = np.asarray(measurement, np.float64)
    steps, label = measurement_steps(calibration.raw, measurement, options.dark, options.bin)
    if steps is None:
        return measurement, []
    return apply_raw_steps(steps, measurement), [f"{label}: {steps.describe()}"]
