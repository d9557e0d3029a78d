"""One solve's observers (clsdcam.solve.tracker), each on its own: the rank, the FFT work against the full solver's
and the skip report's lines, snapshots and progress in data units."""
import numpy as np
import pytest

from clsdcam.backends import NumpyBackend
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.problem import Problem
from clsdcam.solve.tracker import Progress, Ranks, Snapshots, Work
from clsdcam.solve.units import Units

UNITS = Units(measurement=2.0, calibration=4.0)


@pytest.fixture
def model():
    rng = np.random.default_rng(0)
    return ForwardModel(NumpyBackend("float64"), rng.random((6, 7)), rng.random((3, 6, 7)))


def problem_of(model, rank=3):
    return Problem(model, np.random.default_rng(1).random((6, 7)), None, None, rank)


def records(problem, iterations=(1, 2)):
    return [{"iteration": k, "data": 1.0, "objective": 3.0, "transforms": problem.transforms()} for k in iterations]


def test_ranks_puts_the_problems_rank_in_each_record(model):
    record = records(problem_of(model, rank=2))[0]
    Ranks().on_iteration(record, None, problem_of(model, rank=2))
    assert record["rank"] == 2


def test_work_counts_each_iteration_against_the_full_solver_and_the_work_between(model):
    """An iteration's transforms count at this field, and as many gradients of the full solver at the paper's field;
    work between iterations (on_work) counts as done only; notes become the report's lines, in order."""
    problem, work = problem_of(model), Work(model)
    for record in records(problem):
        work.on_iteration(record, None, problem)
    voxels = model.geometry.voxels_per_band
    assert work.report.done_work == 2 * problem.transforms() * voxels
    assert work.report.full_work == 2 * 4 * model.n_bands * work.paper_voxels
    full = work.report.full_work
    work.on_work(5)
    assert work.report.done_work == (2 * problem.transforms() + 5) * voxels and work.report.full_work == full
    work.on_note("field: none cut")
    work.on_note("terms: l1 (zero weight) not computed")
    assert work.report.lines == ["field: none cut", "terms: l1 (zero weight) not computed"]


def test_snapshots_keep_the_cube_in_data_units_at_the_iterations_asked_for(model):
    problem, snapshots = problem_of(model), Snapshots(model, UNITS, iterations=[2])
    for record in records(problem):
        snapshots.on_iteration(record, np.ones(model.cube_shape), problem)
    assert list(snapshots.kept) == [2] and np.all(snapshots.kept[2] == np.float32(0.5))


def test_progress_gets_each_record_in_data_units_and_the_driver_keeps_its_own(model):
    seen, problem = [], problem_of(model)
    progress = Progress(UNITS, seen.append)
    history = records(problem)
    for record in history:
        progress.on_iteration(record, None, problem)
    assert [r["data"] for r in seen] == [4.0, 4.0] and seen[0]["objective"] == 12.0
    assert history[0]["data"] == 1.0 and seen[0]["transforms"] == problem.transforms()
