"""The benchmark's re-implementation of the authors' solver computes the same A as clsdcam."""
import sys
from pathlib import Path

import numpy as np

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.camera.model import ForwardModel
from clsdcam.sim import simulate

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
from authors_baseline import AuthorsReplay, AuthorsSolver, haar_tv_periodic  # noqa: E402


def test_same_forward_and_adjoint_as_clsdcam():
    sim = simulate(scene="leds", shape=(16, 22), n_bands=4, seed=0)
    ours = ForwardModel(NumpyBackend("float64"), sim.calibration.psf, sim.calibration.filters)
    theirs = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)
    field = np.random.default_rng(0).random(ours.cube_shape)
    np.testing.assert_allclose(theirs.forward(np.moveaxis(field, 0, -1)), ours.forward(field), rtol=1e-10, atol=1e-12)
    r = np.random.default_rng(1).random(ours.sensor_shape)
    np.testing.assert_allclose(np.moveaxis(theirs.adjoint(r), -1, 0), ours.adjoint(r), rtol=1e-10, atol=1e-12)


def test_haar_tv_without_threshold_is_the_identity_and_flattens_with_a_large_one():
    x = np.random.default_rng(2).random((6, 8, 4))
    np.testing.assert_allclose(haar_tv_periodic(x, 0.0, 1.0), x, rtol=1e-12)
    flat = haar_tv_periodic(x, 1e3, 1.0)
    assert np.ptp(flat) < np.ptp(x)


def test_the_baseline_run_lowers_the_data_term():
    sim = simulate(scene="leds", shape=(16, 22), n_bands=4, seed=0)
    solver = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)
    cubes = [cube for _, cube in solver.run(sim.measurement, 100)]
    field = np.zeros((32, 44, 4))

    def residual(cube):
        field[8:24, 11:33] = np.moveaxis(cube, 0, -1)
        return np.linalg.norm(solver.forward(field) - sim.measurement)

    assert residual(cubes[-1]) < 0.5 * residual(cubes[0])


def test_the_replay_follows_the_published_iteration_in_float32():
    sim = simulate(scene="target", shape=(24, 32), n_bands=4, seed=0)
    published = AuthorsSolver(sim.calibration.psf, sim.calibration.filters)
    replay = AuthorsReplay(published)
    iterates, forward = [], replay.forward
    replay.forward = lambda v: iterates.append(v.dtype) or forward(v)
    for (_, theirs), (_, ours) in zip(published.run(sim.measurement, 30), replay.run(sim.measurement, 30)):
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-5 * np.abs(theirs).max())
    assert set(iterates) == {np.dtype(np.float32)}           # no NumPy scalar widened the iterate to float64
