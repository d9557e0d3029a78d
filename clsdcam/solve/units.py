"""Solver units and data units, converted in one place.

The solver divides the measurement by s = max|b| and works on b/s, so every array and record inside a solve is in
*solver units*. Two kinds of figure leave it:

* cubes (the result, its snapshots, a video's carried field) in the calibration's units: v_data = v·s/c, with c
  the factor the calibration divided its model by when it normalised the PSF and filters
  (:attr:`clsdcam.camera.calibration.Calibration.scale`); a warm start comes in the other way, v = v_data·c/s;
* records (data term, objective) in the measurement's units squared: ½‖b − Av‖² scales by s².
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Units:
    """The two scales of one solve: ``measurement`` s = max|b| and ``calibration`` c (the calibration's scale)."""

    measurement: float
    calibration: float = 1.0

    @property
    def cube_factor(self) -> float:
        """s/c: a solver-units cube times this is in the calibration's units."""
        return self.measurement / self.calibration

    def to_solver(self, x):
        """A host cube in the calibration's units (a warm start) in solver units: x·c/s."""
        return np.asarray(x) * self.calibration / self.measurement

    @property
    def solver_factor(self) -> float:
        """c/s: a calibration-units cube times this is in solver units."""
        return self.calibration / self.measurement

    def cube(self, x: np.ndarray) -> np.ndarray:
        """A host cube in solver units as a float32 cube in the calibration's units."""
        return (np.asarray(x) * self.cube_factor).astype(np.float32)

    def record(self, record: dict) -> dict:
        """A copy of a driver's record with the data term and objective in data units (×s²)."""
        return {**record, "data": record["data"] * self.measurement ** 2,
                "objective": record["objective"] * self.measurement ** 2}
