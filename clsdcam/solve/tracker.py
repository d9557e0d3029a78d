"""One solve's observers of its driver (:class:`clsdcam.solve.driver.Observer`), each with one job: the rank of each
iteration's space, the FFT work against the full solver's with the skip report's lines, snapshots of the cube, and
progress reports in data units. The solve adds them in that order: the later ones read the rank in the record."""
from __future__ import annotations

from typing import Callable

import numpy as np

from ..camera.geometry import centred_geometry
from .driver import Observer
from .skips import SkipReport
from .units import Units


class Ranks(Observer):
    """Puts the rank of the space each iteration ran in into its record (the history's ``rank``)."""

    def on_iteration(self, record: dict, x, problem) -> None:
        record["rank"] = problem.rank


class Work(Observer):
    """The solve's :class:`~clsdcam.solve.skips.SkipReport`: its notes as lines, and the FFT work done (at this field)
    against the full solver's (at the paper's field, every band)."""

    def __init__(self, model):
        self.report = SkipReport()
        self.voxels = model.geometry.voxels_per_band
        self.paper_voxels = centred_geometry(model.sensor_shape).voxels_per_band
        self.full_transforms = 4 * model.n_bands        # the full solver's gradient (a forward and an adjoint)

    def on_iteration(self, record: dict, x, problem) -> None:
        """The record's transforms (the algorithm's and a checkpoint's), and the same number of gradients in the full
        solver's band space."""
        transforms, per_gradient = record["transforms"], problem.transforms()
        self.count(transforms, transforms * self.full_transforms / per_gradient if per_gradient else 0)

    def on_note(self, line: str) -> None:
        self.report.lines.append(line)

    def on_work(self, transforms: int) -> None:
        """Work the full solver, one space with one L, does not do (power iterations, full-step checks)."""
        self.count(transforms)

    def count(self, transforms: int, full_transforms: int = 0):
        """Add FFT work done (at this field) and the full solver's (at the paper's field)."""
        self.report.done_work += transforms * self.voxels
        self.report.full_work += full_transforms * self.paper_voxels


class Snapshots(Observer):
    """Copies of the cube in data units at the ``iterations`` asked for, in :attr:`kept` by iteration."""

    def __init__(self, model, units: Units, iterations=()):
        self.model, self.units = model, units
        self.iterations = set(iterations)
        self.kept: dict[int, np.ndarray] = {}

    def on_iteration(self, record: dict, x, problem) -> None:
        if record["iteration"] in self.iterations:
            self.kept[record["iteration"]] = self.units.cube(self.model.window(problem.solution(x)))


class Progress(Observer):
    """Each record, in data units, to ``callback`` (the driver's own stay in solver units: its rules compare them)."""

    def __init__(self, units: Units, callback: Callable[[dict], None]):
        self.units, self.callback = units, callback

    def on_iteration(self, record: dict, x, problem) -> None:
        self.callback(self.units.record(record))
