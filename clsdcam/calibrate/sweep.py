"""A monochromator sweep → the per-pixel transmission t_i(y, x) at the sweep's wavelengths λ_i.

Frame i was taken with the monochromator at λ_i, the source at power P(λ_i) and exposure e_i, so

    t_i(y, x) = R_i(y, x) / (p_i · e_i),   p_i = P(λ_i) / max_j P(λ_j),

R_i the frame after the raw steps of :mod:`.raw` (dark removed and clipped at 0, crop, bin). P is the power
CSV (wavelength nm, power in any unit) interpolated linearly onto the λ_i (1 without ``--power``); e_i a
constant or an exposure CSV (wavelength nm, exposure) interpolated the same way (1 without ``--exposure``).
Neither CSV is extrapolated: a table that does not cover the sweep is refused.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError, shape_text
from .frames import Sweep
from ..camera.raw import RawSteps, apply_raw_steps
from .tables import interpolated, read_table


def sweep_wavelengths(spec: str, sweep: Sweep) -> np.ndarray:
    """λ_i from ``START:STOP:STEP`` (nm, STOP included when on the grid) or a CSV (first column), one per frame
    and increasing; InputError otherwise."""
    if Path(spec).exists() or ":" not in spec:
        wavelengths = read_table(spec, "--wavelengths", 1)[:, 0]
    else:
        wavelengths = _grid(spec)
    if wavelengths.size != len(sweep):
        raise InputError(f"sweep {sweep.source}: {len(sweep)} frames but {wavelengths.size} wavelengths ({spec})")
    if wavelengths.size > 1 and np.any(np.diff(wavelengths) <= 0):
        raise InputError(f"--wavelengths {spec}: the wavelengths must increase (frames are in name order)")
    return wavelengths


def _grid(spec: str) -> np.ndarray:
    try:
        start, stop, step = (float(v) for v in spec.split(":"))
    except ValueError:
        raise InputError(f"--wavelengths {spec!r}: expected START:STOP:STEP (nm), e.g. 370:890:2, or a CSV") from None
    if not (step > 0 and stop >= start):
        raise InputError(f"--wavelengths {spec!r}: need STEP > 0 and STOP ≥ START")
    return start + step * np.arange(int(np.floor((stop - start) / step + 1e-9)) + 1)


def power_weights(path, wavelengths: np.ndarray) -> np.ndarray:
    """p_i = P(λ_i) / max_j P(λ_j) from the power CSV (all ones without one)."""
    if path is None:
        return np.ones_like(wavelengths)
    power = interpolated(path, wavelengths, "--power")
    if not np.all(power > 0):
        raise InputError(f"--power {path}: the power must be > 0 over the sweep")
    return power / power.max()


def exposure_weights(spec, wavelengths: np.ndarray) -> np.ndarray:
    """e_i: a constant (``--exposure 0.5``) or a CSV (wavelength, exposure); all ones without it."""
    if spec is None:
        return np.ones_like(wavelengths)
    try:
        exposure = np.full_like(wavelengths, float(spec))
    except ValueError:
        exposure = interpolated(spec, wavelengths, "--exposure")
    if not np.all(exposure > 0):
        raise InputError(f"--exposure {spec}: exposures must be > 0")
    return exposure


@dataclass(frozen=True, eq=False)
class Measured:
    transmission: np.ndarray      # (N, h, w) float32, t_i of the module docstring
    saturated: np.ndarray         # (H, W) bool, raw pixels at the saturation code in some frame
    peak_signal: np.ndarray       # (h, w), max_i R_i: the brightest signal each pixel saw


def measure(sweep: Sweep, steps: RawSteps, weights: np.ndarray, saturation: float | None) -> Measured:
    """Read the frames one by one: t_i = R_i / w_i, with w_i = p_i · e_i; raw pixels ≥ ``saturation`` flagged.
    InputError when nothing is above the dark level in any frame."""
    saturated = np.zeros(sweep.shape, bool)
    transmission, peak = None, None
    for i in range(len(sweep)):
        frame = sweep.frame(i)
        if saturation is not None:
            saturated |= frame >= saturation
        signal = apply_raw_steps(steps, frame)
        if transmission is None:
            transmission, peak = np.empty((len(sweep),) + signal.shape, np.float32), signal
        transmission[i] = signal / weights[i]
        peak = np.maximum(peak, signal)
    if not peak.any():
        raise InputError(f"sweep {sweep.source}: nothing above the dark level in any of its {len(sweep)} "
                         f"{shape_text(sweep.shape)} frames")
    return Measured(transmission, saturated, peak)
