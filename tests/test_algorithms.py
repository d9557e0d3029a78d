"""Algorithms as plug-ins (clsdcam.algorithms): FISTA's momentum; a second algorithm (tests/pgm_algorithm.py, plain
proximal gradient) registered with one line runs in band space and a subspace, on both backends, through
checkpoints, Ctrl-C and warm starts; FISTA runs on a backend without the fusions it prefers."""
import math

import numpy as np
import pytest

from clsdcam.algorithms import ALGORITHMS
from clsdcam.algorithms.fista import next_momentum
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.errors import InputError
from clsdcam.metrics import psnr
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver
from clsdcam.solve.space_policy import WARMUP
from conftest import opencl_device
from pgm_algorithm import ProximalGradient

FUSIONS = ("fista_stats", "extrapolate", "subspace_tv")


@pytest.fixture
def pgm(monkeypatch):
    monkeypatch.setitem(ALGORITHMS, "pgm", ProximalGradient)      # the one registry line


@pytest.fixture(scope="module")
def leds():
    return simulate(scene="leds", shape=(48, 64), n_bands=16, seed=0)


@pytest.fixture(params=["numpy", "opencl"])
def backend(request):
    if request.param == "opencl":
        opencl_device()
    return request.param


def solve(sim, backend="numpy", **settings):
    return Solver(sim.calibration, backend=backend, settings=Settings(**settings)).solve(sim.measurement)


def test_momentum_sequence():
    t = [1.0]
    for _ in range(5):
        t.append(next_momentum(t[-1]))
    expected = [1.0, (1 + math.sqrt(5)) / 2]
    expected.append((1 + math.sqrt(1 + 4 * expected[-1] ** 2)) / 2)
    np.testing.assert_allclose(t[:3], expected, rtol=1e-15)
    # t_k ≥ (k + 1)/2, the bound behind the O(1/k²) rate; the authors' 1 + √(1+4t²)/2 violates t² − t ≤ t_prev²
    assert all(tk >= (k + 2) / 2 for k, tk in enumerate(t))
    assert all(abs(t[k] ** 2 - t[k] - t[k - 1] ** 2) < 1e-12 for k in range(1, len(t)))


def test_an_unknown_algorithm_is_refused():
    with pytest.raises(InputError, match="--algorithm 'sirt': expected one of fista, admm"):
        Settings(algorithm="sirt")


def test_a_plugged_in_algorithm_runs_in_both_spaces(pgm, backend, leds):
    result = solve(leds, backend, iters=60, algorithm="pgm", rank=4)
    ranks = [r["rank"] for r in result.history]
    assert ranks[:WARMUP] == [16] * WARMUP and set(ranks[WARMUP:]) == {4}
    assert "re-read from a full step's spectra 1 times" in result.attrs["skips"]      # a move between bases
    assert "momentum" not in result.history[-1] and result.attrs["restarts"] == 0
    fista = solve(leds, backend, iters=60, rank=4)
    assert 15 < psnr(result.cube, leds.truth) < psnr(fista.cube, leds.truth)     # no momentum: slower, not wrong


def test_checkpoints_back_off_a_plugged_in_algorithm(pgm, leds):
    result = solve(leds, iters=40, algorithm="pgm", step_scale=8.0, objective_every=1)
    assert result.attrs["backoffs"] >= 1 and result.attrs["final_step"] < 8.0 / result.attrs["lipschitz"]
    values = [r["objective"] for r in result.history]
    assert all(b <= a for a, b in zip(values, values[1:])) and values[-1] < values[0]


def test_ctrl_c_stops_a_plugged_in_algorithm_with_its_best_cube(pgm, leds):
    def interrupt(record):
        if record["iteration"] == 15:
            raise KeyboardInterrupt

    solver = Solver(leds.calibration, settings=Settings(iters=40, algorithm="pgm", rank=4))
    result = solver.solve(leds.measurement, progress=interrupt)
    assert result.stop_reason == "interrupted" and result.iterations == 15
    assert np.isfinite(result.cube).all() and result.cube.max() > 0


def test_a_plugged_in_algorithm_warm_starts(pgm, leds):
    solver = Solver(leds.calibration, settings=Settings(iters=40, algorithm="pgm", rank=4))
    first = solver.solve(leds.measurement)
    carried = solver.solve(leds.measurement, state=first.state, iters=5)
    assert carried.history[0]["rank"] == 4 and carried.history[0]["data"] <= 1.01 * first.history[-1]["data"]
    warm = solver.solve(leds.measurement, x0=first.cube, iters=5)
    assert warm.history[0]["data"] < 0.1 * first.history[0]["data"]


class Unfused:
    """A backend without the optional fusions (FUSIONS): every other attribute is the wrapped backend's."""

    def __init__(self, inner):
        self._inner = inner

    def __getattr__(self, name):
        if name in FUSIONS:
            raise AttributeError(name)
        return getattr(self._inner, name)


@pytest.mark.parametrize("rank", [0, 4])
def test_fista_runs_without_the_backends_fusions(leds, rank):
    """The fusions are FISTA's and the subspace's, with fallbacks from primitives: the same solve (float64)."""
    fused = solve(leds, NumpyBackend("float64"), iters=40, rank=rank, dtype="float64")
    unfused = solve(leds, Unfused(NumpyBackend("float64")), iters=40, rank=rank, dtype="float64")
    assert [r["rank"] for r in unfused.history] == [r["rank"] for r in fused.history]
    assert np.linalg.norm(unfused.cube - fused.cube) <= 1e-6 * np.linalg.norm(fused.cube)


@pytest.fixture
def pdhg(monkeypatch):
    from pdhg_algorithm import PrimalDual

    monkeypatch.setitem(ALGORITHMS, "pdhg", PrimalDual)      # the one registry line


def test_a_plugged_in_algorithm_with_a_sub_problem_solves_on_both_backends(pdhg, leds):
    """The primal-dual plug-in (its dual a sub-problem built from the problem's priors) runs cold on NumPy and
    OpenCL to the same cube, and goes on fitting: more iterations, a lower data term and a better cube."""
    opencl_device()
    settings = dict(iters=120, algorithm="pdhg", tv=3e-3)
    results = [solve(leds, backend, **settings) for backend in ("numpy", "opencl")]
    cubes = [result.cube for result in results]
    assert np.linalg.norm(cubes[1] - cubes[0]) <= 1e-4 * np.linalg.norm(cubes[0])
    early = solve(leds, iters=20, algorithm="pdhg", tv=3e-3)
    assert results[0].history[-1]["data"] < 0.6 * early.history[-1]["data"]
    assert 20 < psnr(early.cube, leds.truth) < psnr(cubes[0], leds.truth)


@pytest.mark.parametrize("backend", ["numpy", "opencl"])
def test_a_plugged_in_algorithm_with_a_sub_problem_warm_starts(pdhg, leds, backend):
    """A stream's next frame resumes the plug-in's dual (its carry) and goes on where the last frame stopped: 60 then
    5 iterations land nearer 65 in one solve than with a fresh dual; a cube as x0 starts afresh but near."""
    if backend == "opencl":
        opencl_device()
    solver = Solver(leds.calibration, backend=backend, settings=Settings(iters=60, algorithm="pdhg"))
    first = solver.solve(leds.measurement)
    assert first.state.carry is not None
    state = first.state
    resumed = solver.solve(leds.measurement, state=state, iters=5)
    assert resumed.history[0]["data"] <= 1.01 * first.history[-1]["data"] and state.carry is None
    afresh = solver.solve(leds.measurement, state=state, iters=5)         # the carry was handed over once
    straight = solver.solve(leds.measurement, iters=65).cube
    assert np.linalg.norm(resumed.cube - straight) < 0.5 * np.linalg.norm(afresh.cube - straight)
    warm = solver.solve(leds.measurement, x0=first.cube, iters=5)
    assert warm.history[0]["data"] < 0.1 * first.history[0]["data"]
