"""The Solver (clsdcam.solve.solver): one calibration on one backend, built once; its solves share its model,
Lipschitz constant and store; it refuses a measurement that is not the calibration's."""
import numpy as np
import pytest

from clsdcam.errors import InputError
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver


@pytest.fixture(scope="module")
def sim():
    return simulate(scene="leds", shape=(32, 48), n_bands=4, seed=2)


def test_its_solves_share_the_model_the_lipschitz_constant_and_the_store(sim):
    solver = Solver(sim.calibration, settings=Settings(iters=3, algorithm="admm"))
    model, lipschitz = solver.model, solver.lipschitz
    solver.solve(sim.measurement)
    stored = dict(solver.shared)
    solver.solve(0.5 * sim.measurement)
    assert solver.model is model and solver.lipschitz == lipschitz and stored
    assert all(solver.shared[key] is value for key, value in stored.items())


def test_the_settings_and_the_device_are_recorded_on_every_result(sim):
    result = Solver(sim.calibration, settings=Settings(iters=2)).solve(sim.measurement)
    assert {"backend": "numpy", "iters": 2, "algorithm": "fista"}.items() <= result.attrs.items()


@pytest.mark.parametrize("bad, message", [(np.ones((3, 3)), "does not match calibration"),
                                          (np.full((32, 48), np.nan), "measurement")])
def test_a_measurement_that_is_not_the_calibrations_is_refused(sim, bad, message):
    with pytest.raises(InputError, match=message):
        Solver(sim.calibration, settings=Settings(iters=2)).solve(bad)


def test_a_zero_measurement_gives_a_zero_cube_without_iterating(sim):
    result = Solver(sim.calibration, settings=Settings(iters=5)).solve(np.zeros((32, 48)))
    assert result.stop_reason == "zero measurement" and result.iterations == 0 and not result.cube.any()
