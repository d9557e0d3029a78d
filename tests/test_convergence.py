"""The distance estimate of ``--iters auto`` (clsdcam.solve.convergence) and the driver's "converged" stop."""

import math

import numpy as np
import pytest

from clsdcam.solve.convergence import (FALLBACK_AFTER, RATIOS, TRUSTED, WINDOW, DistanceEstimate, WindowTail,
                                      paired_tail)
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


def settled_zig_zag(pairs=12):
    """A trusted start (steps shrinking by √0.8 a window: pairs of windows by 0.8) and a zig-zag that goes on at the
    same rate a pair, W = 1."""
    rho, count = 0.8 ** 0.5, RATIOS + TRUSTED
    return [rho ** i for i in range(count)], zig_zag(pairs, first=rho ** count * (1 + rho))


def readings(*parts):
    """(the W-window tail, the reported distance) after each step of the last part, the parts fed in turn."""
    estimate, short = DistanceEstimate(window=1), WindowTail(1)
    for part in parts[:-1]:
        for step in part:
            estimate.add(step), short.add(step)
    read = []
    for step in parts[-1]:
        estimate.add(step), short.add(step)
        read.append((short.tail, estimate.distance))
    return read


def test_a_zig_zag_falls_back_on_windows_twice_as_long():
    """Once trusted, the W-window tail goes ∞ at every window of a zig-zag: the first of them reads ∞, every later
    one the tail of 2W windows that end with the window just closed, S·q/(1 − q) with q = rate."""
    start, zig = settled_zig_zag()
    assert math.isfinite(readings(start)[-1][1])
    read = readings(start, zig)
    unknown = next(n for n, (short, _) in enumerate(read) if short == math.inf)
    assert all(short == math.inf for short, _ in read[unknown:])
    assert [distance for _, distance in read[unknown:unknown + FALLBACK_AFTER - 1]] == [math.inf] * (FALLBACK_AFTER - 1)
    assert all(math.isfinite(distance) for _, distance in read[unknown + FALLBACK_AFTER - 1:])
    assert read[-1][1] == pytest.approx(sum(zig[-2:]) * 0.8 / 0.2)            # pairs as the zig-zag made them
    assert read[-2][1] == pytest.approx(sum(zig[-3:-1]) * 0.8 / 0.2)          # pairs across them, just as fresh


def test_a_jump_in_the_last_window_is_not_read_as_converged():
    """During the fallback a window 100 times the one before makes the long windows grow too: ∞, where the tail of
    the pairs closed before it would read a distance lower than any before."""
    start, zig = settled_zig_zag()
    read = readings(start, zig + [zig[-1] * 100])
    assert math.isfinite(read[-2][1]) and read[-1][1] == math.inf


def test_a_finite_tail_ends_the_fallback():
    """After the zig-zag, steps that shrink steadily are judged by the W-window tail again, at once (trusted)."""
    start, zig = settled_zig_zag()
    calm = [zig[-1] * 0.5 ** i for i in range(1, RATIOS + 2)]
    short, distance = readings(start, zig + calm)[-1]
    assert distance == short == pytest.approx(calm[-1])                   # S·q/(1 − q), q = 1/2


def test_one_unknown_tail_after_a_finite_one_is_unknown():
    """The fallback counts unknown tails in a row: after the calm steps, one window that grows reads ∞ again, not
    the 2W-window tail (finite there)."""
    start, zig = settled_zig_zag()
    calm = [zig[-1] * 0.5 ** i for i in range(1, RATIOS + 2)]
    steps = start + zig + calm + [calm[-1] * 1.2]
    short, distance = readings(steps)[-1]
    assert short == distance == math.inf and math.isfinite(paired_tail(steps))


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


@pytest.mark.parametrize("move, converge, given, after", [
    ("widen_stop", 1e-3, 1e-2, 1e-2),          # widened
    ("widen_stop", 1e-2, 1e-3, 1e-2),          # never narrowed
    ("widen_stop", 0.0, 1e-2, 0.0),            # a rule that is off stays off
    ("narrow_stop", 1e-2, 1e-3, 1e-3),         # narrowed
    ("narrow_stop", 1e-3, 1e-2, 1e-3),         # never widened
    ("narrow_stop", 0.0, 1e-3, 0.0),           # a rule that is off stays off
])
def test_the_drivers_stop_moves_only_its_own_way_and_never_turns_on(move, converge, given, after):
    problem = Quadratic(3, m=40, n=40, mu=1e-2)
    driver, functions = problem.driver()
    driver.rules = Rules(converge=converge)
    getattr(driver, move)(given)
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
