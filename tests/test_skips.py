"""What the solver skips, that it says so, and that skipping costs no accuracy on simulated scenes."""
import signal

import numpy as np
import pytest

from clsdcam import Settings, Solver
from clsdcam.metrics import psnr
from clsdcam.phases import CHECK_EVERY, WARMUP, Phases
from clsdcam.sim import simulate


@pytest.fixture(scope="module")
def leds():
    return simulate(scene="leds", shape=(48, 64), n_bands=64, seed=0)


def solve(sim, **settings):
    return Solver(sim.calibration, settings=Settings(**settings)).solve(sim.measurement)


def test_default_solves_three_led_spectra_in_a_small_subspace_at_least_as_well(leds):
    full, fast = solve(leds, iters=150, skip=False), solve(leds, iters=150)
    ranks = [r["rank"] for r in fast.history]
    assert ranks[:WARMUP] == [64] * WARMUP and ranks[WARMUP] <= 16
    assert psnr(fast.cube, leds.truth) >= psnr(full.cube, leds.truth) - 0.2
    assert fast.attrs["fft_work_saved"] > 0.5 and full.attrs["fft_work_saved"] == 0.0
    assert "subspace:" in fast.attrs["skips"] and "field:" in fast.attrs["skips"]
    assert fast.cube.min() >= 0


def test_the_basis_follows_the_full_problem_when_no_widening_is_needed(leds):
    """Checks that do not widen re-estimate the basis at the same rank, so the subspace does not freeze the
    warm-up's spectra: a longer solve keeps improving (and stays at least as good as the full solver)."""
    short, long = solve(leds, iters=100), solve(leds, iters=300)
    assert "re-estimated from a full step" in long.attrs["skips"]
    assert psnr(long.cube, leds.truth) > psnr(short.cube, leds.truth)
    assert psnr(long.cube, leds.truth) >= psnr(solve(leds, iters=300, skip=False).cube, leds.truth) - 0.2


def test_full_solver_uses_the_paper_field_and_every_band(leds):
    result = solve(leds, iters=12, skip=False)
    assert tuple(result.attrs["field_shape"]) == (96, 128)
    assert all(r["rank"] == 64 and r["transforms"] in (256, 384) for r in result.history)


def test_forced_rank_is_kept_and_never_widened(leds):
    result = solve(leds, iters=80, rank=2)
    assert [r["rank"] for r in result.history][WARMUP:] == [2] * (80 - WARMUP)
    assert "--rank 2" in result.attrs["skips"] and "widened" not in result.attrs["skips"]


def test_rank_of_k_or_more_means_band_space(leds):
    result = solve(leds, iters=20, rank=64)
    assert {r["rank"] for r in result.history} == {64} and "subspace:" not in result.attrs["skips"]


def test_a_warm_start_enters_the_subspace_at_once(leds):
    solver = Solver(leds.calibration, settings=Settings(iters=40))
    first = solver.solve(leds.measurement)
    again = solver.solve(leds.measurement, x0=first.cube)
    assert again.history[0]["rank"] < 64
    assert psnr(again.cube, leds.truth) >= psnr(first.cube, leds.truth) - 0.05


def test_fft_work_counts_every_transform(leds):
    result = solve(leds, iters=60)
    field = np.prod(result.attrs["field_shape"])
    done = sum(r["transforms"] for r in result.history) * field
    full = sum(384 if np.isfinite(r["objective"]) else 256 for r in result.history) * 96 * 128
    assert result.attrs["fft_work_saved"] <= 1 - done / full + 1e-12   # the width checks add work too


def test_widening_follows_the_data_and_band_space_is_the_last_resort():
    """A dense scene with many spectra: the subspace grows, or hands back to band space, never loses accuracy."""
    sim = simulate(scene="piecewise", shape=(48, 64), n_bands=16, seed=2)
    full, fast = solve(sim, iters=150, skip=False), solve(sim, iters=150)
    ranks = [r["rank"] for r in fast.history]
    assert ranks[-1] > ranks[WARMUP] and ("widened" in fast.attrs["skips"] or "left" in fast.attrs["skips"])
    assert psnr(fast.cube, sim.truth) >= psnr(full.cube, sim.truth) - 0.1


def test_few_bands_stay_in_band_space():
    sim = simulate(scene="leds", shape=(32, 48), n_bands=3, seed=0)
    assert {r["rank"] for r in solve(sim, iters=20).history} == {3}


@pytest.mark.parametrize("move, after", [("_enter_subspace", WARMUP), ("_check_width", WARMUP + CHECK_EVERY)])
def test_ctrl_c_while_the_iterates_change_space_stops_with_a_whole_cube(leds, monkeypatch, move, after, default_sigint):
    """A SIGINT during a move between spaces lets the move finish, then stops as "interrupted" with the cube of
    the space the iterates are in (it used to escape the solve as a KeyboardInterrupt, losing the cube)."""
    original = getattr(Phases, move)

    def interrupted_move(self, problem):
        signal.raise_signal(signal.SIGINT)
        return original(self, problem)

    monkeypatch.setattr(Phases, move, interrupted_move)
    result = solve(leds, iters=200)
    assert result.stop_reason == "interrupted" and result.iterations == after
    assert "subspace:" in result.attrs["skips"]
    assert np.isfinite(result.cube).all() and result.cube.min() >= 0 and result.cube.max() > 0
