"""The NumPy backend's cache-blocked, threaded kernels against plain whole-array formulas, across many blocks."""
import numpy as np
import pytest

import clsdcam.backends.blocks as blocks
from clsdcam.backends.blocks import map_blocks, spans
from clsdcam.backends.numpy import NumpyBackend


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch):
    """A few rows per block, so every test crosses block and thread boundaries."""
    monkeypatch.setattr(blocks, "BLOCK_BYTES", 1)


def plain_haar_tv(x, tau, weights):
    """The parallel-proximal Haar step written on whole arrays (the definition in NumpyBackend.haar_tv)."""
    active = [(axis, w) for axis, w in enumerate(weights) if w > 0]
    total = np.zeros_like(x)
    for axis, w in active:
        half = np.clip(np.diff(x, axis=axis) / 2, -2 * len(active) * tau * w, 2 * len(active) * tau * w)
        lead = [slice(None)] * 3
        lead[axis] = slice(0, -1)
        trail = [slice(None)] * 3
        trail[axis] = slice(1, None)
        total[tuple(lead)] += half
        total[tuple(trail)] -= half
    return x + (total / (2 * len(active)) if active else 0)


SHAPES = [(5, 17, 9), (1, 8, 3), (3, 1, 7), (4, 2, 1)]
WEIGHTS = [(1.0, 1.0, 1.0), (0.0, 0.5, 2.0), (1.0, 0.0, 0.0), (0.0, 0.0, 0.0)]


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("weights", WEIGHTS)
@pytest.mark.parametrize("nonneg", [False, True])
def test_haar_tv_blocks_match_the_whole_array_formula(shape, weights, nonneg):
    be = NumpyBackend("float64", workers=2)
    x = np.random.default_rng(0).standard_normal(shape)
    expected = plain_haar_tv(x, 0.07, weights)
    expected = np.maximum(expected, 0) if nonneg else expected
    np.testing.assert_allclose(be.haar_tv(x, 0.07, weights, nonneg=nonneg), expected, rtol=1e-13, atol=1e-13)
    aliased = x.copy()
    np.testing.assert_allclose(be.haar_tv(aliased, 0.07, weights, out=aliased, nonneg=nonneg), expected, atol=1e-13)


@pytest.mark.parametrize("shape", SHAPES)
def test_tv_norm_blocks_match_explicit_differences(shape):
    be = NumpyBackend("float64", workers=2)
    x = np.random.default_rng(1).standard_normal(shape)
    weights = (0.5, 2.0, 1.5)
    expected = sum(w * np.abs(np.diff(x, axis=axis)).sum() for axis, w in enumerate(weights))
    assert be.tv_norm(x, weights) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("shape", [(5, 17, 9), (40,), (6, 7)])
def test_fista_stats_and_extrapolate(shape):
    be = NumpyBackend("float32", workers=2)
    rng = np.random.default_rng(2)
    x_new, x_old, y = (rng.standard_normal(shape).astype(np.float32) for _ in range(3))
    d = (x_new - x_old).astype(np.float64)
    expected = (np.sum(d * d), np.sum(x_new.astype(np.float64) ** 2), np.sum((y - x_new).astype(np.float64) * d))
    np.testing.assert_allclose(be.fista_stats(x_new, x_old, y), expected, rtol=1e-6)
    np.testing.assert_allclose(be.extrapolate(x_new, x_old, 0.3), x_new + 0.3 * (x_new - x_old), rtol=1e-6)
    aliased = x_old.copy()
    np.testing.assert_allclose(be.extrapolate(x_new, aliased, 0.3, out=aliased), x_new + 0.3 * (x_new - x_old), rtol=1e-6)


@pytest.mark.parametrize("bands,rank", [(16, 3), (5, 5), (1, 1), (9, 4)])
@pytest.mark.parametrize("weights", WEIGHTS)
def test_subspace_tv_is_projected_haar_tv_of_the_expansion(bands, rank, weights):
    """c⁺ = Bᵀ·max(0, haar_tv(B·c)) with B orthonormal (K × r)."""
    be = NumpyBackend("float64", workers=2)
    rng = np.random.default_rng(3)
    basis = np.linalg.qr(rng.standard_normal((bands, rank)))[0]
    c = rng.standard_normal((rank, 13, 11))
    expected = np.einsum("kj,khw->jhw", basis, np.maximum(plain_haar_tv(np.einsum("kj,jhw->khw", basis, c), 0.05,
                                                                           weights), 0))
    np.testing.assert_allclose(be.subspace_tv(c, basis, 0.05, weights), expected, rtol=1e-12, atol=1e-12)


def test_map_blocks_covers_every_row_once_in_order():
    seen = map_blocks(lambda y0, y1, scratch: (y0, y1), 23, row_bytes=1, workers=3)
    assert [r for y0, y1 in seen for r in range(y0, y1)] == list(range(23))
    assert spans(5, 3) == [(0, 1), (1, 3), (3, 5)] and spans(2, 4) == [(0, 1), (1, 2)]


def test_rectangular_bandmix_expands_and_projects():
    be = NumpyBackend("float64")
    rng = np.random.default_rng(4)
    basis, c = rng.standard_normal((6, 2)), rng.standard_normal((2, 3, 4))
    expanded = be.bandmix(c, basis)
    assert expanded.shape == (6, 3, 4)
    np.testing.assert_allclose(expanded, np.einsum("kj,jhw->khw", basis, c))
    np.testing.assert_allclose(be.bandmix(expanded, basis.T), np.einsum("kj,khw->jhw", basis, expanded))


def test_a_ctrl_c_during_the_blocks_is_raised_once_every_thread_has_finished(default_sigint):
    """A Ctrl-C reaches the main thread while two threads work: it is raised only once no span is running, so
    whatever handles it (the driver putting the best iterate back) is not overwritten afterwards. The span that saw
    it has written its rows; the other, started or not yet when the Ctrl-C came, is whole or untouched."""
    import _thread
    import threading
    import time

    out = np.zeros(4)
    first = threading.Event()

    def work(y0, y1, _scratch):
        if y0 == 0:
            first.set()
            _thread.interrupt_main()          # as a Ctrl-C arriving now
        else:
            first.wait()
        time.sleep(0.3)
        out[y0:y1] = 1.0

    with pytest.raises(KeyboardInterrupt):
        map_blocks(work, 4, row_bytes=1 << 30, workers=2)       # one row a block, two spans
    seen = out.copy()
    time.sleep(0.8)
    assert np.array_equal(out, seen) and np.all(seen[:2] == 1.0) and seen[2] == seen[3]


def test_a_ctrl_c_while_the_spans_are_submitted_lets_nothing_write_after_it(monkeypatch):
    """A Ctrl-C while the second span is being submitted: the first, submitted, either runs to its end before the
    Ctrl-C is raised or never starts; nothing writes after it is raised."""
    import time
    from concurrent.futures import ThreadPoolExecutor

    pool, submitted = ThreadPoolExecutor(2), []

    class InterruptedSubmission:
        def submit(self, fn, *args):
            if submitted:
                raise KeyboardInterrupt        # as a Ctrl-C arriving now
            submitted.append(pool.submit(fn, *args))
            return submitted[-1]

    monkeypatch.setattr(blocks, "_pool", lambda workers: InterruptedSubmission())
    out = np.zeros(4)

    def work(y0, y1, _scratch):
        time.sleep(0.3)
        out[y0:y1] = 1.0

    with pytest.raises(KeyboardInterrupt):
        map_blocks(work, 4, row_bytes=1 << 30, workers=2)
    seen = out.copy()
    time.sleep(0.8)
    assert np.array_equal(out, seen) and not seen[2:].any()
    pool.shutdown()
