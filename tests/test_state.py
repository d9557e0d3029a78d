"""Where a solve starts (clsdcam.solve.state.Start) and what it leaves to the next (SolverState): one plan object for
cold, warm and carried starts."""
import numpy as np

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.solve.priors import build_priors
from clsdcam.solve.reconstruction import Reconstruction
from clsdcam.solve.settings import Settings
from clsdcam.sim import simulate
from clsdcam.solve.solver import Solver
from clsdcam.solve.state import SolverState, Start

BACKEND = NumpyBackend("float32")


def test_a_state_starts_the_next_solve_from_its_field_basis_step_and_weights():
    basis = np.eye(6)[:, :2]
    state = SolverState(field=np.full((6, 4, 4), 2.0, np.float32), basis=basis, core=2, step_factor=0.5,
                        weights={"tv": 1e-3}, fit=0.1, references={"atb_max": 7.0})
    start = state.start(BACKEND, units=0.25)
    np.testing.assert_array_equal(start.field, np.full((6, 4, 4), 0.5, np.float32))
    assert start.warm and start.basis is basis and (start.core, start.step_factor) == (2, 0.5)
    assert start.reference(lambda name: 1.0)("atb_max") == 7.0 and start.reference(lambda name: 1.0)("other") == 1.0


def test_a_start_gives_the_priors_its_weights_and_no_auto_estimate():
    priors = build_priors(BACKEND, Settings(tv="auto"), lambda name: 1.0)
    assert priors[0].auto
    Start(field=None, step_factor=1.0, warm=True, weights={"tv": 2e-3}).apply_weights(priors)
    assert not priors[0].auto and priors[0].relative == 2e-3
    cold = build_priors(BACKEND, Settings(tv="auto"), lambda name: 1.0)
    Start(field=None, step_factor=1.0, warm=False).apply_weights(cold)
    assert cold[0].auto


def test_a_solve_plans_cold_and_warm_starts():
    sim = simulate(scene="leds", shape=(32, 48), n_bands=8, seed=0)
    solver = Solver(sim.calibration, settings=Settings(iters=5, step_scale=0.9))
    cold = Reconstruction(solver, sim.measurement).start()
    assert not cold.warm and cold.basis is None and cold.step_factor == 0.9 and not np.any(cold.field)
    warm = Reconstruction(solver, sim.measurement, x0=np.ones((8, 32, 48))).start()
    assert warm.warm and warm.field.shape == solver.model.cube_shape and warm.field.max() > 0
