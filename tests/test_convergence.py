"""The distance estimate of ``--iters auto`` (clsdcam.solve.convergence) and the driver's "converged" stop."""

import math

import numpy as np
import pytest

from clsdcam.solve.convergence import FALLBACK_AFTER, RATIOS, TRUSTED, WINDOW, DistanceEstimate, WindowTail
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
    tail = WindowTail(WINDOW)
    for i in range(RATIOS * WINDOW):
        tail.add(1.0 / (i + 1))
    assert tail.tail == math.inf                         # RATIOS windows: one ratio short
    for _ in range(WINDOW):
        tail.add(0.5)                                    # a window as long as the one before: q ≥ 1
    assert tail.tail == math.inf


def test_the_slowest_of_the_last_ratios_is_trusted():
    """A window cut short (a FISTA restart: 0.5 → 0.05) is not taken for a fast rate: the slowest ratio is."""
    tail = WindowTail(1)
    for change in (1.0, 0.9, 0.5, 0.05):                 # ratios 0.9, 0.56, 0.1: the tail is judged by 0.9
        tail.add(change)
    assert tail.tail == pytest.approx(0.05 * 0.9 / 0.1)


def halving(estimate, count, start=1.0):
    """Feed ``count`` steps start·2^−i; the distances read after each."""
    return [estimate.add(start * 0.5 ** i) and estimate.distance for i in range(count)]


def test_the_first_finite_tails_are_not_reported():
    """The first finite tail comes with window RATIOS + 1; it and the next TRUSTED − 2 read ∞, then the tail."""
    distances = halving(DistanceEstimate(window=1), RATIOS + TRUSTED)
    assert distances[:RATIOS + TRUSTED - 1] == [math.inf] * (RATIOS + TRUSTED - 1)
    assert distances[-1] == pytest.approx(0.5 ** (RATIOS + TRUSTED - 1))        # S·q/(1 − q), q = 1/2


def test_restart_forgets_the_windows_and_the_trust():
    estimate = DistanceEstimate(window=1)
    halving(estimate, RATIOS + TRUSTED)
    assert math.isfinite(estimate.distance)
    estimate.restart()
    assert halving(estimate, RATIOS + TRUSTED - 1) == [math.inf] * (RATIOS + TRUSTED - 1)
    assert estimate.add(0.01) and math.isfinite(estimate.distance)


def zig_zag(pairs, first, rate=0.8, jump=1.5):
    """Steps in pairs of windows (W = 1): each pair sums ``rate`` times the one before, but within a pair the
    second window is ``jump`` times the first, so every other short ratio is ≥ 1 and the short tail stays ∞."""
    steps = []
    for j in range(pairs):
        total = first * rate ** j
        steps += [total / (1 + jump), total * jump / (1 + jump)]
    return steps


def settled_then(steps):
    """A run trusted first (halving steps), then ``steps``: (the W-window tail, the 2W-window tail, the reported
    distance) after each of ``steps``."""
    estimate, short, long_ = DistanceEstimate(window=1), WindowTail(1), WindowTail(2)
    count = RATIOS + TRUSTED
    trusted = [0.5 ** i for i in range(count + count % 2)]             # an even count: pairs stay aligned
    for step in trusted:
        estimate.add(step), short.add(step), long_.add(step)
    assert math.isfinite(estimate.distance)
    read = []
    for step in steps:
        estimate.add(step), short.add(step), long_.add(step)
        read.append((short.tail, long_.tail, estimate.distance))
    return read


def test_a_zig_zag_falls_back_on_windows_twice_as_long():
    """Once trusted, the W-window tail goes ∞ at every window of a zig-zag; the first FALLBACK_AFTER − 1 of them
    read ∞, the next ones the 2W-window tail, which ends at S·q/(1 − q) with q = rate."""
    steps = zig_zag(12, first=0.1)
    read = settled_then(steps)
    assert all(short == math.inf for short, _, _ in read)
    assert [distance for _, _, distance in read[:FALLBACK_AFTER - 1]] == [math.inf] * (FALLBACK_AFTER - 1)
    assert all(distance == long_ for _, long_, distance in read[FALLBACK_AFTER - 1:])
    assert read[-1][2] == pytest.approx(sum(steps[-2:]) * 0.8 / 0.2)


def test_a_finite_tail_ends_the_fallback():
    """After the zig-zag, steps that shrink steadily are judged by the W-window tail again, at once (trusted)."""
    zig = zig_zag(12, first=0.1)
    calm = [zig[-1] * 0.5 ** i for i in range(1, RATIOS + 2)]
    short, _, distance = settled_then(zig + calm)[-1]
    assert distance == short == pytest.approx(calm[-1])                   # S·q/(1 − q), q = 1/2


def test_one_unknown_tail_after_a_finite_one_is_unknown():
    """The fallback counts unknown tails in a row: after the calm steps, one window that grows reads ∞ again, not
    the 2W-window tail (finite there)."""
    zig = zig_zag(12, first=0.1)
    calm = [zig[-1] * 0.5 ** i for i in range(1, RATIOS + 2)]
    short, long_, distance = settled_then(zig + calm + [calm[-1] * 4])[-1]
    assert short == distance == math.inf and math.isfinite(long_)


def test_no_fallback_before_the_tail_was_trusted():
    """A zig-zag from the start never reads a distance, however long: the long tail needs a settled run first."""
    estimate = DistanceEstimate(window=1)
    assert not any(math.isfinite(estimate.add(step) and estimate.distance) for step in zig_zag(20, first=1.0))


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
