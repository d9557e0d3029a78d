"""The distance estimate of ``--iters auto`` (clsdcam.solve.convergence) and the driver's "converged" stop."""

import math

import numpy as np
import pytest

from clsdcam.solve.convergence import RATIOS, WINDOW, DistanceEstimate
from clsdcam.solve.driver import Rules
from test_driver import Quadratic


def test_a_geometric_sequence_of_steps_gives_its_exact_tail():
    """c_i = ρ^i: after window j the steps still to come sum to S_j·q/(1 − q), q = ρ^W."""
    rho, estimate = 0.97, DistanceEstimate()
    changes = rho ** np.arange(10 * WINDOW)
    closed = [i for i, c in enumerate(changes) if estimate.add(float(c))]
    assert closed == [WINDOW * j - 1 for j in range(1, 11)]
    assert estimate.distance == pytest.approx(changes[10 * WINDOW - 1] * rho / (1 - rho), rel=1e-9)


def test_unknown_until_enough_windows_and_while_the_steps_do_not_shrink():
    estimate = DistanceEstimate()
    for i in range(RATIOS * WINDOW):
        estimate.add(1.0 / (i + 1))
    assert estimate.distance == math.inf                 # RATIOS windows: one ratio short
    for _ in range(WINDOW):
        estimate.add(0.5)                                # a window as long as the one before: q ≥ 1
    assert estimate.distance == math.inf


def test_the_slowest_of_the_last_ratios_is_trusted():
    """A window cut short (a FISTA restart: 0.5 → 0.05) is not taken for a fast rate: the slowest ratio is."""
    estimate = DistanceEstimate(window=1)
    for change in (1.0, 0.9, 0.5, 0.05):                 # ratios 0.9, 0.56, 0.1: the tail is judged by 0.9
        estimate.add(change)
    assert estimate.distance == pytest.approx(0.05 * 0.9 / 0.1)


def test_restart_forgets_the_windows():
    estimate = DistanceEstimate(window=1)
    for change in (1.0, 0.5, 0.25, 0.125):
        estimate.add(change)
    assert math.isfinite(estimate.distance)
    estimate.restart()
    assert estimate.distance == math.inf and estimate.add(0.1) and estimate.distance == math.inf


@pytest.mark.parametrize("converge", [1e-3, 1e-5])
def test_the_driver_stops_converged_within_the_tolerance_of_the_limit(converge):
    """On an ill-conditioned quadratic FISTA (with restart) stops by itself, at a true relative distance to x* of at
    most the tolerance, and the records carry the estimate."""
    problem = Quadratic(3, m=40, n=40, mu=1e-2)
    result = problem.run(iters=20000, converge=converge)
    assert result.stop_reason == "converged" and result.iterations < 20000
    true = np.linalg.norm(result.x - problem.exact) / np.linalg.norm(problem.exact)
    assert true <= converge and result.history[-1]["distance"] < converge
    assert all("distance" in r for r in result.history)


def test_without_the_rule_no_record_carries_a_distance():
    result = Quadratic(1).run(iters=50)
    assert result.stop_reason == "iterations" and not any("distance" in r for r in result.history)


@pytest.mark.parametrize("converge, wider, after", [
    (1e-3, 1e-2, 1e-2),          # widened
    (1e-2, 1e-3, 1e-2),          # never narrowed
    (0.0, 1e-2, 0.0),            # a rule that is off stays off
])
def test_the_drivers_stop_widens_and_never_narrows_or_turns_on(converge, wider, after):
    problem = Quadratic(3, m=40, n=40, mu=1e-2)
    driver, functions = problem.driver()
    driver.rules = Rules(converge=converge)
    driver.widen_stop(wider)
    assert driver.rules.converge == after


def test_a_widened_stop_stops_the_same_run_sooner():
    """From the iteration it is widened, the driver stops at the wider tolerance: the run that widens at
    iteration 20 stops where the run at the wide tolerance does, earlier than the one at the narrow tolerance."""
    problem = Quadratic(3, m=40, n=40, mu=1e-2)
    stops = {}
    for name, (converge, wider) in {"narrow": (1e-5, None), "wide": (1e-3, None), "widened": (1e-5, 1e-3)}.items():
        driver, functions = problem.driver()
        driver.rules = Rules(converge=converge)
        driver.run(functions, 20)
        if wider:
            driver.widen_stop(wider)
        assert driver.run(functions, 20000) == "converged"
        stops[name] = driver.iterations
    assert stops["widened"] == stops["wide"] < stops["narrow"]
