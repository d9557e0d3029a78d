"""Per-iteration bookkeeping of one solve: the rank and FFTs of each iteration, the FFT work against the full
solver's, snapshots of the cube, and progress reports in data units."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..camera.geometry import centred_geometry
from .problem import Problem
from .skips import SkipReport
from .units import Units


class Tracker:
    """Per-iteration bookkeeping: data units, rank and FFTs of each iteration, snapshots, progress, FFT work."""

    def __init__(self, model, units: Units, snapshots=(), progress: Callable[[dict], None] | None = None):
        """``units``: the solve's :class:`~clsdcam.solve.units.Units` (snapshots and progress leave in data units)."""
        self.model = model
        self.units = units
        self.snapshots = set(snapshots)
        self.progress = progress
        self.kept: dict[int, np.ndarray] = {}
        self.report = SkipReport()
        self.voxels = model.geometry.voxels_per_band
        self.paper_voxels = centred_geometry(model.sensor_shape).voxels_per_band
        self.full_transforms = 4 * model.n_bands        # the full solver's gradient (a forward and an adjoint)

    def on(self, problem: Problem):
        """The driver's on_iteration callback for iterations in ``problem``'s space: adds the rank to the record
        and counts the transforms the algorithm and checkpoints report, against the same work in the full solver's
        band space (its numbers stay in solver units: the driver's rules compare them); progress gets data units."""
        per_gradient = problem.transforms()

        def on_iteration(record: dict, x):
            record["rank"] = problem.rank
            transforms = record["transforms"]
            self.count(transforms, transforms * self.full_transforms / per_gradient if per_gradient else 0)
            if record["iteration"] in self.snapshots:
                self.kept[record["iteration"]] = self.units.cube(self.model.window(problem.solution(x)))
            if self.progress is not None:
                self.progress(self.units.record(record))
        return on_iteration

    def count(self, transforms: int, full_transforms: int = 0):
        """Add FFT work done (at this field) and the full solver's (at the paper's field)."""
        self.report.done_work += transforms * self.voxels
        self.report.full_work += full_transforms * self.paper_voxels
