"""The driver (clsdcam.solve.driver) running FISTA: a closed-form problem, stopping rules, checkpoints, back-off,
Ctrl-C, moves between spaces, and the events its observers hear."""

import numpy as np
import pytest

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.algorithms.fista import Fista
from clsdcam.solve.driver import Driver, Functions, Observer, Rules, minimize

BACKEND = NumpyBackend("float64")


class Quadratic:
    """min ½‖Ax − b‖² + (μ/2)‖x‖², solved by x* = (AᵀA + μI)⁻¹Aᵀb."""

    def __init__(self, seed, m=30, n=12, mu=0.3):
        rng = np.random.default_rng(seed)
        self.a, self.b, self.mu = rng.standard_normal((m, n)), rng.standard_normal(m), mu
        self.lipschitz = np.linalg.norm(self.a, 2) ** 2
        self.exact = np.linalg.solve(self.a.T @ self.a + mu * np.eye(n), self.a.T @ self.b)

    def gradient_step(self, y, out, step):
        residual = self.a @ y - self.b
        out[...] = y - step * (self.a.T @ residual)
        return 0.5 * residual @ residual

    def prox(self, z, step, out):  # prox of step·(μ/2)‖x‖²
        out[...] = z / (1 + step * self.mu)

    def objective(self, x):
        residual = self.a @ x - self.b
        return 0.5 * residual @ residual + 0.5 * self.mu * x @ x

    def run(self, step_scale=1.0, **kwargs):
        return minimize(self.gradient_step, self.prox, BACKEND, np.zeros_like(self.exact),
                        step=step_scale / self.lipschitz, **kwargs)

    def driver(self):
        """FISTA under the driver, from zero, with step 1/L and F checkpoints; and this problem for it."""
        rules = Rules()
        fista = Fista(BACKEND, np.zeros_like(self.exact), 1 / self.lipschitz, rules)
        return Driver(fista, rules, self.objective), Functions(self.gradient_step, self.prox)


@pytest.mark.parametrize("restart", [False, True])
def test_fista_quadratic_prior_reaches_closed_form(restart):
    problem = Quadratic(0)
    result = problem.run(iters=3000, restart=restart, objective=problem.objective)
    np.testing.assert_allclose(result.x, problem.exact, rtol=1e-8, atol=1e-10)
    assert result.stop_reason == "iterations" and result.iterations == 3000


def test_restart_fires_and_speeds_up_an_ill_conditioned_problem():
    problem = Quadratic(3, m=40, n=40, mu=1e-4)
    errors = {}
    for restart in (False, True):
        result = problem.run(iters=400, restart=restart)
        errors[restart] = np.linalg.norm(result.x - problem.exact)
        assert any(r["restart"] for r in result.history) == restart
    assert errors[True] < 0.5 * errors[False]


def test_fista_stops_on_tolerance_and_records_history():
    problem = Quadratic(1)
    result = problem.run(iters=5000, tol=1e-6)
    assert result.stop_reason == "tolerance" and result.iterations < 5000
    assert result.history[-1]["change"] < 1e-6
    assert [r["iteration"] for r in result.history] == list(range(1, result.iterations + 1))
    assert np.linalg.norm(result.x - problem.exact) / np.linalg.norm(problem.exact) < 1e-4


def test_fista_should_stop_callback():
    problem = Quadratic(2)
    calls = []
    result = problem.run(iters=100, should_stop=lambda: "custom" if len(calls.append(1) or calls) >= 7 else None)
    assert result.stop_reason == "custom" and result.iterations == 7


def test_recorded_objective_never_rises_without_restart():
    problem = Quadratic(4, m=40, n=40, mu=1e-3)
    result = problem.run(iters=600, restart=False, objective=problem.objective, objective_every=3)
    values = [r["objective"] for r in result.history if np.isfinite(r["objective"])]
    assert all(b <= a for a, b in zip(values, values[1:]))
    assert any(r["rollback"] for r in result.history)  # plain FISTA does rise here: the checkpoint caught it


@pytest.mark.parametrize("step_scale", [3.0, 50.0, 1e4])
def test_too_large_a_step_is_backed_off_and_the_run_converges(step_scale):
    problem = Quadratic(5)
    result = problem.run(step_scale=step_scale, iters=3000, objective=problem.objective)
    backoffs = sum(r["backoff"] for r in result.history)
    assert backoffs >= 1 and result.step <= 2.0 / problem.lipschitz
    assert result.stop_reason == "iterations" and np.all(np.isfinite(result.x))
    np.testing.assert_allclose(result.x, problem.exact, rtol=1e-6, atol=1e-8)


def test_a_checkpoint_after_a_rollback_must_lower_the_objective_or_the_step_is_halved():
    """Rise → rollback; then a value equal to the best (no decrease beyond round-off) → back-off; then progress."""
    problem = Quadratic(9)
    values = iter([10.0, 9.0, 9.5, 9.0, 8.0, 7.0])   # x0, then one checkpoint per iteration
    result = problem.run(iters=5, objective=lambda x: next(values), objective_every=1)
    assert [(r["rollback"], r["backoff"]) for r in result.history] == [
        (False, False), (True, False), (True, True), (False, False), (False, False)]
    assert result.step == pytest.approx(0.5 / problem.lipschitz)


def test_ctrl_c_returns_the_best_iterate():
    problem = Quadratic(6)

    def interrupt(record, x):
        if record["iteration"] == 25:
            raise KeyboardInterrupt

    result = problem.run(iters=100, objective=problem.objective, objective_every=10, on_iteration=interrupt)
    # iteration 25 was done when its callback (the progress line) was interrupted: it counts
    assert result.stop_reason == "interrupted" and result.iterations == 25
    best = min(r["objective"] for r in result.history)
    assert problem.objective(result.x) == pytest.approx(best, rel=1e-12)


def test_a_run_in_phases_through_an_identity_change_of_space_is_the_same_run():
    """Driver.move keeps FISTA's x, x_prev, y and t: phases joined by the identity reproduce one run exactly."""
    problem = Quadratic(7, m=40, n=40, mu=1e-3)
    whole = problem.run(iters=120, objective=problem.objective)
    driver, functions = problem.driver()
    for mapping in (lambda a: a.copy(), lambda a: a, lambda a: a.copy(), lambda a: a):
        assert driver.run(functions, 30) is None
        driver.move(mapping, 1 / problem.lipschitz, problem.objective)
    assert driver.iterations == 120
    np.testing.assert_array_equal(driver.x, whole.x)


def test_a_change_of_space_of_the_same_size_writes_into_the_iterates_arrays():
    """No new arrays when the space keeps its size (the mapping's own results aside), distinct ones when it
    changes; a change of objective keeps the iterates and momentum and scores x under the new objective."""
    problem = Quadratic(7, m=40, n=40, mu=1e-3)
    driver, functions = problem.driver()
    fista, checkpoints = driver.algorithm, driver.checkpoints

    def arrays():
        return [fista.x, fista.x_prev, fista.y, fista.z, checkpoints.best]

    driver.run(functions, 10)
    before = arrays()
    driver.move(lambda a: a.copy(), 1 / problem.lipschitz, problem.objective)
    assert all(a is b for a, b in zip(before, arrays()))
    x, t = fista.x.copy(), fista.t
    driver.rescore(lambda v: 2 * problem.objective(v))
    assert fista.t == t and checkpoints.best_objective == pytest.approx(2 * problem.objective(x))
    np.testing.assert_array_equal(checkpoints.best, x)
    driver.move(lambda a: a[:20].copy(), 1 / problem.lipschitz)
    assert fista.x.shape == (20,) and len({id(a) for a in arrays()}) == 5


def test_fista_stops_on_an_objective_plateau():
    problem = Quadratic(8)
    result = problem.run(iters=5000, objective=problem.objective, plateau=1e-9)
    assert result.stop_reason == "plateau" and 10 < result.iterations < 5000
    checked = [r["objective"] for r in result.history if np.isfinite(r["objective"])]
    assert checked[-2] - checked[-1] < 1e-9 * abs(checked[-1])


class Recorder(Observer):
    """Every event it hears, in order; at each iteration, whether the record was in the history already."""

    def __init__(self, driver=None):
        self.driver, self.events = driver, []

    def on_iteration(self, record, x, problem):
        self.events.append(("iteration", record["iteration"], record is self.driver.history[-1], problem))

    def on_note(self, line):
        self.events.append(("note", line))

    def on_work(self, transforms):
        self.events.append(("work", transforms))


def test_observers_hear_each_iteration_note_and_work_in_the_order_they_were_added():
    problem = Quadratic(4)
    driver, functions = problem.driver()
    first, second = Recorder(driver), Recorder(driver)
    driver.observe(first)
    driver.note("a line", None, "another")
    driver.observe(second)
    driver.work(12)
    driver.run(functions, 2)
    heard = [("work", 12), ("iteration", 1, True, functions), ("iteration", 2, True, functions)]
    assert first.events == [("note", "a line"), ("note", "another")] + heard and second.events == heard


class Counted(Functions):
    """A problem whose gradient costs 4 transforms."""

    def transforms(self):
        return 4


class Costly(Fista):
    """An algorithm that declares its own cost."""

    def transforms(self, problem):
        return 7


@pytest.mark.parametrize("algorithm, per_iteration", [(Fista, 4), (Costly, 7)])
def test_the_record_counts_the_algorithms_declared_transforms_and_a_checkpoints_forward(algorithm, per_iteration):
    problem = Quadratic(5)
    rules = Rules(objective_every=3)
    driver = Driver(algorithm(BACKEND, np.zeros_like(problem.exact), 1 / problem.lipschitz, rules), rules,
                    problem.objective)
    driver.run(Counted(problem.gradient_step, problem.prox), 6)
    assert [r["transforms"] for r in driver.history] == [per_iteration + 2 * (k in (1, 3, 6)) for k in range(1, 7)]


def test_minimize_adapts_its_on_iteration_function_into_an_observer():
    problem = Quadratic(6)
    seen = []
    result = problem.run(iters=3, on_iteration=lambda record, x: seen.append((record, x.copy())))
    assert [record for record, _ in seen] == result.history
    np.testing.assert_array_equal(seen[-1][1], result.x)
