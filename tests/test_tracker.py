"""Per-iteration bookkeeping (clsdcam.solve.tracker): the rank, the FFT work against the full solver's, snapshots
and progress in data units."""
import numpy as np

from clsdcam.backends import NumpyBackend
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.problem import Problem
from clsdcam.solve.tracker import Tracker
from clsdcam.solve.units import Units


def test_each_iteration_is_counted_and_reported_in_data_units():
    rng = np.random.default_rng(0)
    be = NumpyBackend("float64")
    model = ForwardModel(be, rng.random((6, 7)), rng.random((3, 6, 7)))
    seen = []
    tracker = Tracker(model, Units(measurement=2.0, calibration=4.0), snapshots=[2], progress=seen.append)
    problem = Problem(model, rng.random((6, 7)), None, None, 3)
    on_iteration = tracker.on(problem)
    x = np.ones(model.cube_shape)
    for k in (1, 2):
        on_iteration({"iteration": k, "data": 1.0, "objective": 3.0, "transforms": problem.transforms()}, x)
    assert [r["data"] for r in seen] == [4.0, 4.0] and seen[0]["objective"] == 12.0 and seen[0]["rank"] == 3
    assert list(tracker.kept) == [2] and np.all(tracker.kept[2] == np.float32(0.5))
    assert tracker.report.done_work == 2 * problem.transforms() * model.geometry.voxels_per_band
    assert tracker.report.full_work > 0
