"""ADMM (clsdcam.algorithms.admm): each closed-form step against a brute-force solve of its
sub-problem on a tiny case (in one block and in row blocks), the differences' adjoints, convergence to the problem's
minimiser (FISTA's, where both are exact), and the solve around it (driver, checkpoints, Ctrl-C, warm starts, what it
refuses)."""
import dataclasses
import sys
import types

import numpy as np
import pytest
import scipy.fft
import scipy.linalg

from clsdcam.algorithms import admm
from clsdcam.algorithms.admm import balance
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.errors import InputError
from clsdcam.metrics import psnr
from clsdcam.camera.model import ForwardModel
from clsdcam.solve.priors import Sparsity, TotalVariation
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver
from clsdcam.solve.state import SolverState
from clsdcam.backends import blocks
from clsdcam.algorithms.admm.host_steps import (Splitting, difference, difference_adjoint_add, difference_rms,
                                               sweep_bands)
from clsdcam.algorithms.admm.jit_steps import JitSplitting
from clsdcam.algorithms.admm.terms import TERMS_KEY, CalibrationTerms, Penalties, SplitState, band_degrees, band_pivots

RNG = np.random.default_rng(7)


STEPS = {"numpy": Splitting, "compiled": JitSplitting}


def camera_steps(kind, rng, dtype="float64", n_bands=3, shape=(4, 5), tv_weights=(1.0, 0.5, 2.0)):
    """(model, ``kind``'s steps) on an ``n_bands``-band camera of ``shape`` pixels on its doubled field: PSF, filters
    and a positive b drawn from ``rng`` in that order, TV with ``tv_weights`` (None: no TV) and L1, on two threads,
    with fixed penalties, each TV axis its own."""
    psf, filters = rng.random(shape), rng.random((n_bands,) + shape)
    model = ForwardModel(NumpyBackend(dtype), psf, filters)
    tv = None if tv_weights is None else TotalVariation(model.backend, 0.05, Settings(tv_weights=tv_weights))
    split = kind(model, rng.random(shape), CalibrationTerms(model, filters), tv=tv,
                 l1=Sparsity(model.backend, 0.4, None), workers=2)
    split.set_penalties(Penalties(data=0.3, tv=0.7, nonneg=1.3, tv_balance=(0.6, 1.7, 1.2)))
    return model, split


@pytest.fixture(params=[(blocks_, steps) for blocks_ in ("whole", "row blocks") for steps in STEPS],
                ids=lambda param: "-".join(param))
def tiny(request, monkeypatch):
    """A 3-band camera of 4×5 pixels on its 8×10 field, float64, TV on every axis, a positive b, on two threads: in
    one block, or one row per block (every halo row crossing a block's edge); NumPy's steps or the compiled ones."""
    layout, steps = request.param
    if layout == "row blocks":
        monkeypatch.setattr(blocks, "BLOCK_BYTES", 1)
    return camera_steps(STEPS[steps], RNG)


def dense(operator, shape) -> np.ndarray:
    """The matrix of a linear ``operator`` on arrays of ``shape``, column by column."""
    n = int(np.prod(shape))
    columns = []
    for i in range(n):
        e = np.zeros(n)
        e[i] = 1.0
        columns.append(np.ravel(operator(e.reshape(shape))))
    return np.stack(columns, axis=1)


def differences(split, v) -> np.ndarray:
    return np.stack([difference(v, axis, np.empty_like(v)) for axis in split.axes])


STATE_ARRAYS = ("v", "hv", "x", "xi", "rho", "w", "eta", "s", "rest")


def random_state(split) -> SplitState:
    """A state of ``split``'s shapes, every array random (normal); Ŷ the spectrum of a random field."""
    state, _ = split.start(RNG.random(split.shape))
    for name in STATE_ARRAYS:
        getattr(state, name)[...] = RNG.standard_normal(getattr(state, name).shape)
    state.data_spectrum[...] = scipy.fft.rfft2(RNG.standard_normal(split.shape))
    return state


def data_input(split, state) -> np.ndarray:
    """x − ξ over the field, as the host keeps it after the splits: irfft2(Ŷ) and the window's change in ``hv``."""
    h, w = split.sensor_shape
    field = scipy.fft.irfft2(state.data_spectrum, s=split.field_shape)
    field[:, :h, :w] += state.hv
    return field


def grid_argmin(cost, q, grid=np.linspace(-12, 12, 240001)) -> float:
    return grid[np.argmin(cost(grid) + (grid - q) ** 2 / 2)]


def test_the_differences_and_their_adjoints_agree(tiny):
    _, split = tiny
    v, u = RNG.standard_normal(split.shape), RNG.standard_normal(split.shape)
    for axis in (0, 1, 2):
        back = np.zeros_like(v)
        difference_adjoint_add(u, axis, 1.0, back)
        assert np.vdot(difference(v, axis, np.empty_like(v)), u) == pytest.approx(np.vdot(v, back), rel=1e-12)
    assert np.all(difference(v, 0, np.empty_like(v))[-1] == 0)                   # no difference past the last band
    np.testing.assert_allclose(difference(v, 2, np.empty_like(v))[..., -1], v[..., 0] - v[..., -1])  # circular


def test_the_x_differences_along_row_runs_match_the_columnwise_ones_bit_for_bit():
    """Along x, D and Dᵀ work on each plane's rows as one run; into a strided ``out`` (no run to write) and from a
    block of a cube's rows they give exactly the column-wise results, in float32 as the solver runs."""
    cube = RNG.standard_normal((5, 9, 7)).astype(np.float32)
    block, u = cube[:, 2:6], RNG.standard_normal((5, 4, 7)).astype(np.float32)
    strided = np.empty((5, 4, 9), np.float32)[..., :7]
    expected = difference(block, 2, strided)
    np.testing.assert_array_equal(difference(block, 2, np.empty((5, 4, 7), np.float32)), expected)
    np.testing.assert_array_equal(expected[..., :-1], block[..., 1:] - block[..., :-1])
    columnwise = np.ones_like(u)
    columnwise -= 0.3 * u
    columnwise[..., 1:] += 0.3 * u[..., :-1]
    columnwise[..., 0] += 0.3 * u[..., -1]
    np.testing.assert_array_equal(difference_adjoint_add(u, 2, 0.3, np.ones_like(u), scratch={}), columnwise)
    wide = np.ones_like(u)                                   # a float64 scale: the products formed in float64
    wide -= np.float64(0.3) * u
    wide[..., 1:] += np.float64(0.3) * u[..., :-1]
    wide[..., 0] += np.float64(0.3) * u[..., -1]
    np.testing.assert_array_equal(difference_adjoint_add(u, 2, np.float64(0.3), np.ones_like(u), scratch={}), wide)
    fortran = np.asfortranarray(u)                           # no scratch, u in another layout
    np.testing.assert_array_equal(difference_adjoint_add(fortran, 2, 0.3, np.ones_like(u)), columnwise)


def test_the_c_step_solves_its_normal_equations(tiny):
    """(μ₁HᵀH + Σ_d μ₂,dD_dᵀD_d + μ₃I)v = μ₁Hᵀ(x − ξ) + Σ_d μ₂,dD_dᵀs_d + μ₃(w − ρ) (x − ξ from Ŷ and the window's
    change in ``hv``, μ₃(w − ρ) in ``rest``; each axis with its own TV penalty), against a dense solve; then Ŷ the
    relaxed y = αHv + (1 − α)(x − ξ), and ``hv`` its window."""
    _, split = tiny
    p, shape, (h, w) = split.penalties, split.shape, split.sensor_shape
    state = random_state(split)
    H = dense(split.convolve, shape)
    D = [dense(lambda e, a=axis: difference(e, a, np.empty_like(e)), shape) for axis in split.axes]
    mu = [p.tv_along(axis) for axis in split.axes]
    system = p.data * H.T @ H + sum(m * d.T @ d for m, d in zip(mu, D)) + p.nonneg * np.eye(H.shape[0])
    before = data_input(split, state)
    rhs = p.data * H.T @ np.ravel(before) + sum(m * d.T @ np.ravel(s) for m, d, s in zip(mu, D, state.s)) \
        + np.ravel(state.rest)
    expected = np.linalg.solve(system, rhs)
    split.c_step(state)
    tolerance = 1e-9 * np.abs(expected).max()
    hv = (H @ expected).reshape(shape)
    relaxed = split.relaxation * hv + (1 - split.relaxation) * before
    np.testing.assert_allclose(np.ravel(state.v), expected, atol=tolerance)
    np.testing.assert_allclose(scipy.fft.irfft2(state.data_spectrum, s=split.field_shape), relaxed, atol=tolerance)
    np.testing.assert_allclose(state.hv, relaxed[:, :h, :w], atol=tolerance)


@pytest.mark.parametrize("n_bands", [1, 2, 3, 64])
def test_the_band_sweeps_solve_each_tridiagonal_system_in_float32_as_well_as_its_conditioning_allows(n_bands):
    """sweep_bands on band_pivots, in float32 as the solver runs (r and the pivots rounded to it), against a float64
    banded solve of (a·I + e·D_λᵀD_λ)v = r at each of 300 coefficients, a from 10⁴ down to 10⁻⁵ of e: every error
    within 4κ·ε₃₂·‖v‖, κ = (a + e·Λ_max)/a the system's condition number (Λ_max = 2 − 2cos(π(K − 1)/K), the
    Laplacian's largest eigenvalue; κ up to 4·10⁵). Measured over 60 seeds: up to 1.4 κ·ε₃₂ (K = 2), 0.76 at
    K = 64. With no coupling, v = r·(1/a) per band."""
    rng = np.random.default_rng(11)
    a, e = np.logspace(-5, 4, 300), 1.0
    r = rng.standard_normal((n_bands, a.size)) + 1j * rng.standard_normal((n_bands, a.size))
    v = sweep_bands(r.astype(np.complex64), band_pivots(a, e, n_bands).astype(np.float32), np.float32(e), {})
    off, largest = -e * np.ones(n_bands - 1), 2 - 2 * np.cos(np.pi * (n_bands - 1) / n_bands)
    for i in range(a.size):
        bands = np.vstack([np.r_[0.0, off], a[i] + e * band_degrees(n_bands), np.r_[off, 0.0]])
        exact = scipy.linalg.solve_banded((1, 1), bands, r[:, i])
        kappa = (a[i] + e * largest) / a[i]
        assert np.linalg.norm(v[:, i] - exact) <= 4 * kappa * np.finfo(np.float32).eps * np.linalg.norm(exact)
    np.testing.assert_allclose(sweep_bands(r.copy(), band_pivots(a, 0.0, n_bands), 0.0, {}), r / a, rtol=1e-15)
    assert band_degrees(1).tolist() == [0.0] and band_degrees(4).tolist() == [1.0, 2.0, 2.0, 1.0]


def test_h_is_the_models_convolution_in_the_window(tiny):
    """Hv's sensor window, filtered and summed, is A·v: the x-split's frame is the model's."""
    model, split = tiny
    v = RNG.random(split.shape)
    h, w = split.sensor_shape
    filtered = np.einsum("khw,khw->hw", split.filters, split.convolve(v)[:, :h, :w])
    np.testing.assert_allclose(filtered, model.forward(v), rtol=1e-10)


@pytest.mark.parametrize("alpha", [1.0, 1.7])
def test_the_splits_minimise_their_problems(tiny, alpha):
    """Against brute force, each split at its over-relaxed point (α·K v + (1 − α)·z + dual, z the split's last value:
    x, u = s + η, w): x_p = argmin ½(b_p − f_pᵀx_p)² + μ₁/2‖x_p − q_p‖² (a K×K solve per pixel of the window, where
    the host keeps the data split), u = argmin τw_d|u| + μ₂,d/2(u − q)², w = argmin τ₁|w| + ι(w ≥ 0) + μ₃/2(w − q)²
    (grid searches); each dual = q − z, and what the c-step reads: x − ξ (in ``hv`` its change over the relaxed
    y = αHv + (1 − α)(x − ξ) that the c-step left there and in Ŷ), s = u − η, μ₃(w − ρ); the data term at v and w's
    change."""
    _, split = tiny
    p, (h, w) = split.penalties, split.sensor_shape
    state = random_state(split)
    u = state.s + state.eta
    relaxed = state.hv.copy()                                           # y, on the window
    hv = (relaxed - (1 - alpha) * (state.x - state.xi)) / alpha
    q_x = alpha * hv + (1 - alpha) * state.x + state.xi
    q_u = alpha * differences(split, state.v) + (1 - alpha) * u + state.eta
    q_w = alpha * state.v + (1 - alpha) * state.w + state.rho
    fitted = np.einsum("khw,khw->hw", split.filters, hv)
    w_before = state.w.copy()
    data, (step, norm) = split.splits(state, alpha)
    assert data == pytest.approx(0.5 * np.sum((fitted - split.b) ** 2), rel=1e-12)
    x = q_x.copy()
    for i in range(h):
        for j in range(w):
            f = split.filters[:, i, j]
            x[:, i, j] = np.linalg.solve(np.outer(f, f) + p.data * np.eye(3), f * split.b[i, j] + p.data * q_x[:, i, j])
    np.testing.assert_allclose(state.x, x, atol=1e-12)
    np.testing.assert_allclose(state.xi, q_x - x, atol=1e-12)
    np.testing.assert_allclose(state.hv, x - (q_x - x) - relaxed, atol=1e-12)
    for i, axis in enumerate(split.axes):
        weight = split.tv.weight * split.tv.axis_weights[axis] / p.tv_along(axis)
        u = np.array([grid_argmin(lambda g: weight * np.abs(g), q) for q in q_u[i].ravel()[:40]])
        np.testing.assert_allclose(state.eta[i].ravel()[:40], q_u[i].ravel()[:40] - u, atol=2e-4)
        np.testing.assert_allclose(state.s[i], (q_u[i] - state.eta[i]) - state.eta[i], atol=1e-12)
    w_new = np.array([grid_argmin(lambda g: 0.4 / p.nonneg * np.abs(g) + 1e9 * (g < 0), q) for q in q_w.ravel()[:40]])
    np.testing.assert_allclose(state.w.ravel()[:40], w_new, atol=2e-4)
    np.testing.assert_allclose(state.rho, q_w - state.w, atol=1e-12)
    np.testing.assert_allclose(state.rest, p.nonneg * (state.w - state.rho), atol=1e-12)
    assert (step, norm) == pytest.approx((np.sum((state.w - w_before) ** 2), np.sum(state.w ** 2)), rel=1e-12)


@pytest.fixture(scope="module")
def leds():
    return simulate(scene="leds", shape=(32, 40), n_bands=8, seed=3)


def solve(sim, **settings):
    return Solver(sim.calibration, settings=Settings(dtype="float64", **settings)).solve(sim.measurement)


def test_admm_and_fista_reach_the_same_minimiser_where_both_are_exact():
    """With L1 and non-negativity only (FISTA's prox is then exact), both converge to min ½‖Av − b‖² + τ‖v‖₁ + ι(v≥0)
    on a small camera (FISTA's F at 6000 iterations equals its F at 20 000 to 1e-11): the same objective, cubes
    within 1.5 % (ADMM's tail is slow: 1.9 % at 3000 iterations, 0.9 % at 4000)."""
    sim = simulate(scene="leds", shape=(16, 20), n_bands=4, seed=3)
    exact = dict(tv=0.0, l1=1e-2, skip=False, objective_every=1)
    fista = solve(sim, iters=6000, **exact)
    split = solve(sim, iters=4000, algorithm="admm", **exact)
    assert split.history[-1]["objective"] == pytest.approx(fista.history[-1]["objective"], rel=1e-4)
    assert np.linalg.norm(split.cube - fista.cube) < 0.015 * np.linalg.norm(fista.cube)


def test_the_host_runs_the_compiled_passes_where_numba_imports_and_numpys_otherwise(monkeypatch, request):
    host_steps = admm.algorithm.host_steps
    request.addfinalizer(host_steps.cache_clear)
    assert host_steps() is JitSplitting
    host_steps.cache_clear()
    monkeypatch.delitem(sys.modules, "clsdcam.algorithms.admm.jit_steps")
    monkeypatch.setitem(sys.modules, "numba", None)             # import numba raises ImportError
    assert host_steps() is Splitting
    monkeypatch.undo()                                          # Numba imports again: the choice was made once
    assert host_steps() is Splitting


@pytest.mark.parametrize("tv_weights", [(1.0, 0.5, 2.0), (1.0, 1.0, 0.0), (1.0, 0.0, 0.0), None],
                         ids=["every axis", "not λ", "x only", "no TV"])
@pytest.mark.parametrize("dtype", ["float32", "float64"])
def test_the_compiled_passes_match_numpys_from_one_random_state(monkeypatch, dtype, tv_weights):
    """From the same random state of a 5-band camera of 6×7 pixels, in one-row blocks on two threads: the splits
    (over-relaxed) and the TV adjoint, on every TV axis, some or none, leave the same arrays as NumPy's, bit for bit
    but the x-step's (whose sums over the bands run in float64 where NumPy's einsum rounds to the cube's precision:
    within float32's elementwise rule, 2·10⁻⁶ of the array's largest), and return the same sums to that rule; the
    solve along λ (with and without TV along λ's coupling) leaves its three spectra within that rule (complex
    products rounded their own way)."""
    monkeypatch.setattr(blocks, "BLOCK_BYTES", 1)
    steps = [camera_steps(kind, np.random.default_rng(9), dtype, 5, (6, 7), tv_weights)[1]
             for kind in (Splitting, JitSplitting)]
    numpy_state = random_state(steps[0])
    states = [numpy_state, dataclasses.replace(numpy_state, **{name: getattr(numpy_state, name).copy()
                                                               for name in STATE_ARRAYS})]
    rule = 2e-6 if dtype == "float32" else 1e-12
    sums = [split.splits(state, 1.7) for split, state in zip(steps, states)]
    for split, state in zip(steps, states):
        split._add_tv_adjoint(state)
    np.testing.assert_allclose(np.hstack([sums[1][0], sums[1][1]]), np.hstack([sums[0][0], sums[0][1]]), rtol=rule)
    for name in STATE_ARRAYS:
        ours, numpys = getattr(states[1], name), getattr(states[0], name)
        assert ours.dtype == numpys.dtype
        if name in ("hv", "x", "xi"):
            assert np.abs(ours - numpys).max() <= rule * np.abs(numpys).max(), name
        else:
            np.testing.assert_array_equal(ours, numpys, err_msg=name)
    spectra = [numpy_state.data_spectrum, numpy_state.data_spectrum[::-1], numpy_state.data_spectrum * 0.5]
    solved = [[np.array(a) for a in spectra] for _ in steps]
    for split, arrays in zip(steps, solved):
        split._band_solve(*arrays)
    for ours, numpys in zip(*solved[::-1]):
        assert np.abs(ours - numpys).max() <= rule * np.abs(numpys).max()


@pytest.mark.parametrize("dtype, tolerance", [("float64", 1e-12), ("float32", 1e-5)])
def test_the_compiled_passes_solve_as_numpys_do(leds, monkeypatch, dtype, tolerance):
    """150 iterations of ADMM (its balance at 30 included) on the compiled passes, against the same on NumPy's:
    cubes within float64's rounding, and within 10⁻⁵ in float32 (relative L2; measured 1.1·10⁻⁶; OpenCL's parity
    holds 10⁻⁴)."""
    def run():
        return Solver(leds.calibration, settings=Settings(dtype=dtype, iters=150, algorithm="admm")).solve(
            leds.measurement)

    compiled = run()
    monkeypatch.setattr(admm.algorithm, "host_steps", lambda: Splitting)
    reference = run()
    assert np.linalg.norm(compiled.cube - reference.cube) <= tolerance * np.linalg.norm(reference.cube)


def test_admm_solves_with_the_driver(leds, default_sigint):
    """Through the solver: no rollback on a rise (its objective may rise), the history's numbers, a PSNR no worse
    than FISTA's at the same iterations; Ctrl-C returns the best cube so far; a warm start begins near the end."""
    result = solve(leds, iters=60, algorithm="admm", objective_every=1)
    fista = solve(leds, iters=60, objective_every=1)
    assert result.attrs["rollbacks"] == 0 and result.attrs["algorithm"] == "admm"
    assert all(r["transforms"] == 4 * 8 + (4 * 8) // 2 for r in result.history)     # 4K, and F's forward
    assert psnr(result.cube, leds.truth) >= psnr(fista.cube, leds.truth)

    def interrupt(record):
        if record["iteration"] == 12:
            raise KeyboardInterrupt

    solver = Solver(leds.calibration, settings=Settings(iters=40, algorithm="admm"))
    stopped = solver.solve(leds.measurement, progress=interrupt)
    assert stopped.stop_reason == "interrupted" and stopped.iterations == 12 and stopped.cube.max() > 0
    warm = solver.solve(leds.measurement, x0=result.cube, iters=3)
    assert warm.history[0]["data"] < 0.2 * result.history[0]["data"]
    assert warm.history[0]["data"] > result.history[-1]["data"]                  # from a cube: duals afresh


def test_a_videos_next_frame_resumes_the_splits_and_duals(leds):
    """The state carries ADMM's splits and duals: the next frame goes on where the last stopped (its data term at
    the first iteration no higher than the last one's, where fresh duals raise it); the carry is handed over once, so
    a second start from that state starts afresh."""
    solver = Solver(leds.calibration, settings=Settings(iters=30, algorithm="admm"))
    first = solver.solve(leds.measurement)
    state = first.state
    assert state.carry is not None
    resumed = solver.solve(leds.measurement, state=state, iters=3)
    assert resumed.history[0]["data"] <= 1.01 * first.history[-1]["data"]
    assert resumed.attrs["tv_chosen"] == first.attrs["tv_chosen"] and "noise_estimate" not in resumed.attrs
    again = solver.solve(leds.measurement, state=state, iters=3)
    assert state.carry is None and again.history[0]["data"] > 1.2 * first.history[-1]["data"]


def test_a_frame_whose_field_moved_starts_its_duals_afresh_in_the_last_frames_penalties(leds):
    """What a moved field keeps of ADMM's carry (``SplitState.moved``) is its penalties: the next solve starts its
    duals afresh (its first data term well above the last one's, as from a cube) in those penalties, balanced and in
    the probe's reading, and sets them neither anew nor again at the balance's mark; without them it would."""
    solver = Solver(leds.calibration, settings=Settings(iters=admm.algorithm.BALANCE_AT + 5, algorithm="admm"))
    first = solver.solve(leds.measurement)
    carried = first.state.carry[0].penalties
    assert carried.tv_balance is not None and first.state.carry[0].moved() is carried
    moved = dataclasses.replace(first.state, carry=(carried, first.state.carry[1]))
    resumed = solver.solve(leds.measurement, state=moved, iters=admm.algorithm.BALANCE_AT + 2)
    assert resumed.state.carry[0].penalties == carried
    assert resumed.history[0]["data"] > 1.2 * first.history[-1]["data"]
    fresh = solver.solve(leds.measurement, state=dataclasses.replace(first.state, carry=None),
                         iters=admm.algorithm.BALANCE_AT + 2)
    assert fresh.state.carry[0].penalties != carried


@pytest.mark.parametrize("scene", ["spread", "point_like", "few_points"])
def test_the_balance_sets_each_axis_threshold_from_the_iterates_differences_and_keeps_the_unscaled_duals(tiny, scene):
    """After the balance, each axis's soft threshold τw_d/μ₂,d is C times the RMS of D_d w (its β_d within the range; C
    the wider ones on a point-like scene and on a scene of a few points), the splits u_d = s_d + η_d and the unscaled
    duals μ₂,d·η_d are as before, and the state records the penalties its duals are in; the pivots and the coupling
    along λ are the new penalties'."""
    model, split = tiny
    state = random_state(split)
    state.w *= 0.02                    # differences whose threshold the range does not hold
    old = split.penalties
    u, unscaled = state.s + state.eta, [old.tv_along(a) * state.eta[i] for i, a in enumerate(split.axes)]
    rounding = 1e-12 * (np.abs(state.s).max() + np.abs(state.eta).max())    # s + η may cancel to near 0
    new = balance.balance(split, state, model.backend, scene)
    c = {"spread": balance.THRESHOLD_OVER_RMS, "point_like": balance.THRESHOLD_POINT_LIKE,
         "few_points": balance.THRESHOLD_FEW_POINTS}[scene]
    for i, axis in enumerate(split.axes):
        rms = np.sqrt(np.mean(difference(state.w, axis, np.empty_like(state.w)) ** 2))
        assert split.threshold(axis) == pytest.approx(c * rms, rel=1e-12)
        assert np.allclose(new.tv_along(axis) * state.eta[i], unscaled[i], rtol=1e-12, atol=1e-15)
    assert len(set(new.tv_balance)) == 3 and all(b != 1.0 for b in new.tv_balance)
    assert np.allclose(state.s + state.eta, u, rtol=0, atol=rounding)
    assert state.penalties is new and split.penalties is new
    assert split._pivots is split.terms.for_penalties(new, split.axes).pivots and split.coupling == new.tv_along(0)


def test_a_new_nonneg_penalty_keeps_the_unscaled_dual_and_the_right_hand_side_it_implies(tiny):
    """repenalise (a point-like scene's μ₃): the unscaled dual μ₃ρ as before, ``rest`` the new μ₃'(w − ρ') where it
    was μ₃(w − ρ), every other array untouched; the pivots and the state's penalties the new."""
    model, split = tiny
    state = random_state(split)
    old = split.penalties
    state.rest[...] = old.nonneg * (state.w - state.rho)          # what the last w-step left
    before = {name: getattr(state, name).copy() for name in ("v", "hv", "x", "xi", "w", "eta", "s", "data_spectrum")}
    unscaled = old.nonneg * state.rho
    new = balance.repenalise(split, state, model.backend, dataclasses.replace(old, nonneg=0.3 * old.nonneg))
    assert np.allclose(new.nonneg * state.rho, unscaled, rtol=1e-12, atol=1e-15)
    assert np.allclose(state.rest, new.nonneg * (state.w - state.rho), rtol=1e-12, atol=1e-14)
    assert all(np.array_equal(getattr(state, name), value) for name, value in before.items())
    assert state.penalties is new and split.penalties is new
    assert split._pivots is split.terms.for_penalties(new, split.axes).pivots


def test_a_new_data_penalty_keeps_the_unscaled_dual_and_the_data_term_it_implies(tiny):
    """repenalise with μ₁ → μ₁' (and every other penalty with it): the unscaled dual μ₁ξ as before, the c-step's
    x − ξ the new x − ξ' on the sensor window where it was x − ξ (a change in ``hv``), Ŷ and x untouched."""
    model, split = tiny
    state = random_state(split)
    (h, w), old = split.sensor_shape, split.penalties
    split_x = data_input(split, state)
    split_x[:, :h, :w] += state.xi
    kept, unscaled = {name: getattr(state, name).copy() for name in ("x", "data_spectrum")}, old.data * state.xi
    new = balance.repenalise(split, state, model.backend, old.scaled(0.4))
    assert new.data == pytest.approx(0.4 * old.data, rel=1e-15) and new.tv_balance == old.tv_balance
    assert np.allclose(new.data * state.xi, unscaled, rtol=1e-12, atol=1e-15)
    split_x[:, :h, :w] -= state.xi
    assert np.allclose(data_input(split, state), split_x, rtol=1e-12, atol=1e-14)
    assert all(np.array_equal(getattr(state, name), value) for name, value in kept.items())
    assert split._gain is split.terms.for_penalties(new, split.axes).gain


@pytest.mark.parametrize("penalty", ["nonneg", "every"])
def test_new_penalties_leave_the_fixed_point_where_it_is(tiny, penalty):
    """ADMM's fixed point (the splits and the unscaled duals) does not depend on the penalties: a state at it, carried
    to another μ₃ (or every penalty times 0.5) by repenalise, stays there (w moves by round-off), where the same state
    with the duals carried and ``rest`` and ``hv`` not, or started afresh (zero duals) in the new penalties, leaves
    it."""
    model, split = tiny
    state, _ = split.start(np.zeros(split.shape))
    for _ in range(20000):                                         # to a change of w under 1e-14 (its b is random)
        _, (step, norm) = split.iterate(state)
        if 0 < norm and step <= 1e-28 * norm:
            break
    at = state.w.copy()
    moved = lambda s: np.linalg.norm(s.w - at) / np.linalg.norm(at)
    split.iterate(state)
    assert moved(state) < 1e-12                                    # converged
    stale, _ = split.start(at)
    for name in ("v", "hv", "x", "xi", "rho", "w", "eta", "s", "rest"):
        getattr(stale, name)[...] = getattr(state, name)
    old = split.penalties
    balance.repenalise(split, state, model.backend,
                       dataclasses.replace(old, nonneg=0.3 * old.nonneg) if penalty == "nonneg" else old.scaled(0.5))
    for name in ("rho", "xi", "eta", "s"):                         # the duals carried, the right-hand sides not
        getattr(stale, name)[...] = getattr(state, name)
    fresh, _ = split.start(at)
    for s in (state, stale, fresh):
        for _ in range(3):                      # a dual reaches w one iteration after it enters the right-hand side
            split.iterate(s)
    assert moved(state) < 1e-10 and moved(stale) > 1e-4 and moved(fresh) > 1e-4


def test_the_balance_reads_the_rms_of_the_differences_along_each_active_axis():
    """rms(D_d w), summed one band at a time in w's precision, against the differences formed in float64: along λ
    the last one 0 (a single band: 0), along y and x circular; only the active axes are read."""
    for bands, dtype, rel in ((5, np.float32, 1e-6), (5, np.float64, 1e-12), (1, np.float32, 1e-6)):
        w = (RNG.random((bands, 12, 16)) ** 3).astype(dtype)
        exact = w.astype(np.float64)
        differences = {0: np.concatenate([np.diff(exact, axis=0), np.zeros((1,) + w.shape[1:])]),
                       1: np.roll(exact, -1, axis=1) - exact, 2: np.roll(exact, -1, axis=2) - exact}
        for axes in ([0, 1, 2], [1, 2]):
            rms = difference_rms(types.SimpleNamespace(axes=axes), w)
            assert sorted(rms) == axes
            for axis in axes:
                assert rms[axis] == pytest.approx(np.sqrt(np.mean(differences[axis] ** 2)), rel=rel, abs=0.0)


def test_the_balance_holds_each_axis_within_its_range_and_leaves_a_flat_axis(tiny):
    """A cube flat along λ keeps β_λ; the other axes' β_d are held within [1/BALANCE_RANGE, BALANCE_RANGE], or on a
    scene of a few points within [FLOOR_FEW_POINTS, BALANCE_RANGE], the floor the balance then takes."""
    model, split = tiny
    w = np.broadcast_to(RNG.random(split.shape[1:]), split.shape).copy()
    betas = balance.balanced_penalties(split, difference_rms(split, w), balance.THRESHOLD_OVER_RMS).tv_balance
    assert betas[0] == split.penalties.tv_balance[0]
    tiny_rms = balance.balanced_penalties(split, {1: 1e-12, 2: 1e12}, balance.THRESHOLD_OVER_RMS).tv_balance
    assert tiny_rms[1:] == (balance.BALANCE_RANGE, 1.0 / balance.BALANCE_RANGE)
    few = balance.balanced_penalties(split, {1: 1e-12, 2: 1e12}, balance.THRESHOLD_FEW_POINTS,
                                     balance.FLOOR_FEW_POINTS).tv_balance
    assert few[1:] == (balance.BALANCE_RANGE, balance.FLOOR_FEW_POINTS) and balance.FLOOR_FEW_POINTS < tiny_rms[2]
    state = random_state(split)
    state.w *= 1e6                     # differences far above the weight: every axis at its floor
    floors = []
    for scene in ("spread", "point_like", "few_points"):
        fresh = random_state(split)
        fresh.w[...] = state.w
        floors.append(balance.balance(split, fresh, model.backend, scene).tv_balance)
    assert floors == [(1.0 / balance.BALANCE_RANGE,) * 3] * 2 + [(balance.FLOOR_FEW_POINTS,) * 3]


def test_admm_balances_once_at_its_mark_and_a_resumed_frame_keeps_the_penalties(leds, monkeypatch):
    """A solve past BALANCE_AT iterations balances once, at that mark (the record of every later iteration is
    after it); a solve that ends before it keeps the camera's penalties; the next frame resumes with the balanced
    penalties and does not balance again."""
    done, calls = [0], []                # iterations recorded; the iterations done when the balance ran
    real = balance.balance
    monkeypatch.setattr(balance, "balance", lambda *a: calls.append(done[0]) or real(*a))
    progress = lambda record: done.__setitem__(0, record["iteration"])
    at = admm.algorithm.BALANCE_AT
    solver = Solver(leds.calibration, settings=Settings(iters=at, algorithm="admm"))
    short = solver.solve(leds.measurement, progress=progress)
    assert not calls and short.state.carry[0].penalties.tv_balance is None
    solver = Solver(leds.calibration, settings=Settings(iters=at + 5, algorithm="admm"))
    first = solver.solve(leds.measurement, progress=progress)
    carried = first.state.carry[0].penalties
    assert calls == [at] and carried.tv_balance is not None
    resumed = solver.solve(leds.measurement, state=first.state, iters=at + 5, progress=progress)
    assert calls == [at] and resumed.state.carry[0].penalties is carried


def test_a_solver_builds_the_calibrations_terms_once_and_a_fresh_solver_gives_the_same_cube(leds):
    """A video's frames reuse the solver's CalibrationTerms and, for the same penalties, the same pivot arrays;
    the reuse changes nothing: a second solve matches a new solver's bit for bit."""
    solver = Solver(leds.calibration, settings=Settings(iters=4, algorithm="admm"))
    first = solver.solve(leds.measurement)
    terms = solver.shared[TERMS_KEY]
    pivots = terms._last[1].pivots
    second = solver.solve(0.5 * leds.measurement)
    assert solver.shared[TERMS_KEY] is terms and terms._last[1].pivots is pivots
    fresh = Solver(leds.calibration, settings=Settings(iters=4, algorithm="admm")).solve(0.5 * leds.measurement)
    assert np.array_equal(second.cube, fresh.cube) and not np.array_equal(first.cube, second.cube)


def test_the_carry_follows_the_measurements_units(leds):
    """A carry in one solve's units reaches the next in its units, as the field does (the state stores the factor to
    the calibration's units; the start multiplies by the new solve's), and resuming scales every array by it."""
    state = SolverState(np.ones(2), None, 0, 1.0, carry=("arrays", 3.0))
    assert state.start(NumpyBackend("float64"), 0.5).carry == ("arrays", 1.5)
    split = Solver(leds.calibration, settings=Settings(iters=1, algorithm="admm")).solve(leds.measurement).state
    arrays = split.carry[0]
    before = {name: getattr(arrays, name).copy() for name in ("v", "xi", "eta", "rho", "s", "rest")}
    algorithm = admm.Admm(NumpyBackend("float32"), arrays.w, 1.0, None)
    algorithm.resume(arrays, 0.25)
    assert all(np.array_equal(getattr(arrays, name), 0.25 * value) for name, value in before.items())


@pytest.mark.parametrize("settings, message", [
    (dict(subspace=True), "runs in band space"),
    (dict(rank=4), "runs in band space"),
    (dict(lowrank=0.01, spectral=0.1), "steps for --tv and --l1 only, not --lowrank, --spectral"),
])
def test_what_admm_refuses_in_settings(settings, message):
    with pytest.raises(InputError, match=message):
        Settings(algorithm="admm", **settings)
