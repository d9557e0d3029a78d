"""Video streams: chunks that keep warm starts, the solver state carried from frame to frame, motion
prediction at sub-pixel drift, the per-frame stopping rule and the cold start's budget."""
import h5py
import numpy as np
import pytest
import scipy.ndimage as ndi

from clsdcam.batch import BatchSpec, run_batch
from clsdcam.batch.motion import drift, moved_field, predict, predict_state, shifted
from clsdcam.batch.parts import MAX_CHUNK, chunks
from clsdcam.batch.spec import COLD_ITERS
from clsdcam.camera.calibration import Preprocessing, preprocess
from clsdcam.sim.video import simulate_video, write_video
from clsdcam.solve.solver import Settings, Solver
from clsdcam.solve.state import SolverState


def smooth_cube(shape=(3, 48, 64), seed=0):
    """A band-limited random cube (Gaussian-blurred noise): what Fourier shifts move exactly."""
    return ndi.gaussian_filter(np.random.default_rng(seed).random(shape), (0, 3, 3)).astype(np.float32)


# ---- chunks --------------------------------------------------------------------------------------
def test_a_short_batch_gets_one_chunk_per_worker():
    """4 frames on 2 workers: two chunks of 2 (the old rule, missing / (2·workers), gave 4 single frames: no
    frame warm-started); 8 frames on 2 workers: two runs of 4."""
    assert chunks(list(range(4)), None, 2) == [(0, 2), (2, 4)]
    assert chunks(list(range(8)), None, 2) == [(0, 4), (4, 8)]
    assert chunks(list(range(3)), None, 4) == [(0, 1), (1, 2), (2, 3)]


def test_a_long_batch_is_cut_into_runs_of_max_chunk_and_chunk_wins():
    assert chunks(list(range(1000)), None, 2) == [(s, min(s + MAX_CHUNK, 1000)) for s in range(0, 1000, MAX_CHUNK)]
    assert chunks(list(range(8)), 3, 2) == [(0, 3), (3, 6), (6, 8)]
    assert chunks([0, 1, 5, 6, 7], None, 1) == [(0, 2), (5, 8)]     # a resume: contiguous runs only


# ---- motion --------------------------------------------------------------------------------------
@pytest.mark.parametrize("d", [(0.3, -0.45), (0.6, 0.0), (-1.7, 2.2)])
def test_prediction_moves_a_shifted_cube_by_the_shift(d):
    """x̂(t−1) = x̂(t−2) moved by d: the drift is read within 0.1 px and the prediction is x̂(t−1) moved by d
    again (compared with the cube moved by 2d, and by the drift between prediction and x̂(t−1))."""
    before = smooth_cube()
    previous = shifted(before, d)
    np.testing.assert_allclose(drift(before, previous), d, atol=0.1)
    prediction = predict(before, previous)
    np.testing.assert_allclose(drift(previous, prediction), d, atol=0.1)
    np.testing.assert_allclose(prediction, shifted(before, (2 * d[0], 2 * d[1])), atol=0.02 * before.max())


def test_no_drift_or_no_history_keeps_the_cube():
    cube = smooth_cube()
    assert predict(None, cube) is cube and predict(cube, cube) is cube


def test_a_state_field_in_a_subspace_moves_through_its_coefficients():
    """With an orthonormal basis B the field's coefficients are moved: B·shift(Bᵀv) = shift(v) for v in span(B)."""
    basis = np.linalg.qr(np.random.default_rng(1).random((6, 2)))[0]
    coefficients = smooth_cube((2, 40, 56))
    field = np.einsum("kr,ryx->kyx", basis, coefficients).astype(np.float32)
    d = (0.4, -0.7)
    from clsdcam.batch.motion import phase_shift

    np.testing.assert_allclose(moved_field(field, basis, d), phase_shift(field, d), atol=1e-5)


class SplitsCarried:
    """An algorithm's carry: splits and duals, of which a moved field keeps ``kept``."""

    def __init__(self, kept):
        self.kept = kept

    def moved(self):
        return self.kept


def test_predict_state_moves_the_field_and_keeps_what_the_carry_keeps_of_itself():
    """The field moves with the drift; the step, weights and fit stay; an algorithm's carry is reduced to its
    ``moved()`` (ADMM's penalties: its duals belong to the unmoved field), with its units, or dropped when that is
    None."""
    from clsdcam.backends.numpy import NumpyBackend

    before, d = smooth_cube(), (0.5, 0.5)
    state = SolverState(field=before.copy(), basis=None, core=0, step_factor=0.8, weights={"tv": 1e-3}, fit=0.01,
                        carry=(SplitsCarried("penalties"), 2.0))
    moved = predict_state(before, shifted(before, d), state, NumpyBackend(np.float32))
    np.testing.assert_allclose(drift(state.field, moved.field), d, atol=0.1)
    assert (moved.step_factor, moved.weights, moved.fit, moved.carry) == (0.8, {"tv": 1e-3}, 0.01, ("penalties", 2.0))
    state.carry = (SplitsCarried(None), 2.0)
    assert predict_state(before, shifted(before, d), state, NumpyBackend(np.float32)).carry is None
    assert predict_state(None, before, state, NumpyBackend(np.float32)) is state


# ---- the solver: budget and stopping rule ----------------------------------------------------------
@pytest.fixture(scope="module")
def leds():
    calibration, frames, truth = simulate_video("leds", 3, (24, 32), 8, seed=2, drift=(0.3, 0.6))
    calibration, _ = preprocess(calibration, frames[0], Preprocessing())
    return Solver(calibration, settings=Settings(iters=30)), frames


def test_iters_overrides_the_settings_for_one_solve(leds):
    solver, frames = leds
    assert solver.solve(frames[0], iters=7).iterations == 7 and solver.solve(frames[0]).iterations == 30


def test_a_fit_already_reached_stops_at_once_and_an_unreachable_one_never(leds):
    solver, frames = leds
    first = solver.solve(frames[0])
    easy = solver.solve(frames[1], state=first.state, stop_at_fit=1.0)
    assert easy.stop_reason == "fit" and easy.iterations == 1
    hard = solver.solve(frames[1], state=first.state, stop_at_fit=1e-9)
    assert hard.stop_reason == "iterations" and hard.iterations == 30
    assert 0 < first.state.fit == first.attrs["relative_residual"]


# ---- the batch: cold budget, warm frames, state carried ------------------------------------------------
def test_each_chunk_starts_cold_with_the_cold_budget_and_warms_the_rest(tmp_path):
    calibration, frames, truth = simulate_video("leds", 6, (24, 32), 8, seed=3, drift=(0.3, 0.6))
    paths = write_video(tmp_path, calibration, frames, truth)
    spec = BatchSpec(frames=(str(paths["frames"]),), calibration=str(paths["calibration"]),
                     settings=Settings(iters=5))
    run_batch(spec, tmp_path / "out.h5", workers=0, chunk=3)
    with h5py.File(tmp_path / "out.h5", "r") as f:
        warm, iterations = f["warm"][...], f["iterations"][...]
    # serial chunks continue one stream: only frame 0 is cold
    assert warm.tolist() == [False] + [True] * 5
    assert iterations[0] == COLD_ITERS and (iterations[1:] <= 5).all()
    assert spec.budget(warm=False) == COLD_ITERS and BatchSpec(("f",), "c", settings=Settings(iters=99)).budget(False) == 99


# ---- raw frames in a batch --------------------------------------------------------------------------
def test_batch_applies_dark_and_bin_to_each_frame_as_reconstruct_does(tmp_path):
    """Frames at twice the calibration's size with a dark level: ``batch --dark 3 --bin 2`` solves each frame as
    ``prepare`` makes it (the same path as ``reconstruct``), frame by frame."""
    from clsdcam.calibrate.measurement import prepare
    from clsdcam.cli import main

    calibration, frames, truth = simulate_video("leds", 2, (12, 16), 4, seed=4, drift=(0.3, 0.6))
    raw = np.repeat(np.repeat(frames, 2, axis=1), 2, axis=2) + 3.0           # binned 2×2 and dark 3 → frames
    calibration.save(tmp_path / "cal.h5")
    np.save(tmp_path / "raw.npy", raw)
    out = tmp_path / "out.h5"
    assert main(["batch", str(tmp_path / "raw.npy"), "--calibration", str(tmp_path / "cal.h5"), "-o", str(out),
                 "--workers", "0", "--quiet", "--iters", "5", "--cold-iters", "5", "--no-warm-start",
                 "--dark", "3", "--bin", "2"]) == 0
    with h5py.File(out, "r") as f:
        got = f["cubes"][...]
    for i in range(2):
        prepared, b = prepare(raw[i], tmp_path / "cal.h5", Preprocessing(dark=3.0, bin=2))
        np.testing.assert_allclose(b, frames[i], rtol=1e-6, atol=1e-6)
        expected = Solver(prepared, settings=Settings(iters=5)).solve(b).cube
        np.testing.assert_allclose(got[i], expected, rtol=1e-5, atol=1e-6 * expected.max())
