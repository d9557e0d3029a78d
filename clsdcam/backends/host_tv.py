"""Weighted anisotropic 3-D TV on row blocks of (K, H, W) cubes: the host's prox and norm kernels.

The parallel-proximal Haar step (Kamilov 2016) over the D axes d with weight w_d > 0
(cube axes λ, y, x), with full differences e_d(i) = clip(x_{i+e_d} − x_i, ±4Dτw_d)
(e_d = 0 where a neighbour is missing):

    out_i = x_i + 1/(4D) Σ_d (e_d(i) − e_d(i − e_d))

which is the average over the 2D shifted 1-level Haar transforms of soft-thresholding
their detail coefficients (see ``NumpyBackend.haar_tv``). A block is every band of rows
[y0, y0 + n) given with the row above and below it when they exist ("halo" rows), so the
block's result needs nothing else; its temporaries stay in cache.
"""
from __future__ import annotations

import numpy as np

from .blocks import map_blocks, scratch_buffer as buffer


def haar_limits(tau: float, weights) -> tuple[list, float]:
    """(clip bound of the full differences per axis, None where inactive; the 1/(4D) scale)."""
    active = [w > 0 for w in weights]
    d = sum(active)
    limits = [4.0 * d * tau * w if on else None for w, on in zip(weights, active)]
    return limits, (1.0 / (4 * d) if d else 0.0)


def halo(n_rows: int, y0: int, y1: int) -> tuple[int, int]:
    """(rows above, rows below) block [y0, y1) can borrow from a cube of n_rows rows."""
    return int(y0 > 0), int(y1 < n_rows)


def haar_block(xh: np.ndarray, top: int, n: int, limits, scale: float, scratch: dict) -> np.ndarray:
    """out = x + scale·Σ_d (e_d(i) − e_d(i − e_d)) for the n core rows of ``xh`` (core starts at row ``top``)."""
    k, rows, w = xh.shape
    core = xh[:, top:top + n]
    total = buffer(scratch, "total", (k, n, w), xh.dtype)
    terms = 0
    for edges in _clipped_edges(xh, top, n, limits, scratch):
        if terms == 0:
            np.subtract(edges[1], edges[0], out=total)    # e(i) − e(i − 1)
        else:
            total += edges[1]
            total -= edges[0]
        terms += 1
    if terms == 0:
        total[...] = core
        return total
    total *= scale
    total += core
    return total


def _clipped_edges(xh, top, n, limits, scratch):
    """Per active axis, (e(i − 1), e(i)) views over the core: clipped differences, zero past a border."""
    k, rows, w = xh.shape
    core = xh[:, top:top + n]
    dtype = xh.dtype
    lam, lim_y, lim_x = limits
    if lam is not None:
        e = buffer(scratch, "e_lambda", (k + 1, n, w), dtype)
        e[0] = 0
        e[k] = 0
        _clipped_difference(core[1:], core[:-1], e[1:k], lam)
        yield e[:-1], e[1:]
    if lim_y is not None:
        e = buffer(scratch, "e_y", (k, n + 1, w), dtype)
        first, last = 1 - top, min(n, rows - 1 - top)       # edge j joins rows top + j − 1 and top + j
        e[:, :max(first, 0)] = 0
        e[:, last + 1:] = 0
        if first <= last:
            _clipped_difference(xh[:, top + first:top + last + 1], xh[:, top + first - 1:top + last], e[:, first:last + 1], lim_y)
        yield e[:, :-1], e[:, 1:]
    if lim_x is not None:      # along each plane's core rows as one run of n·W values: long inner loops
        m = n * w
        e = buffer(scratch, "e_x", (k, m + 1), dtype)
        run = core.reshape(k, m)
        e[:, 0] = 0
        _clipped_difference(run[:, 1:], run[:, :-1], e[:, 1:m], lim_x)
        e[:, w::w] = 0         # the differences across a row's end, and past the last column
        yield e[:, :-1].reshape(k, n, w), e[:, 1:].reshape(k, n, w)


def _clipped_difference(after, before, out, limit):
    np.subtract(after, before, out=out)
    np.clip(out, -limit, limit, out=out)


def tv_block_norm(xh: np.ndarray, top: int, n: int, weights) -> float:
    """Σ_d w_d Σ |x_{i+e_d} − x_i| over the differences owned by the n core rows (forward neighbours), float64."""
    k, rows, w = xh.shape
    core = xh[:, top:top + n]
    below = min(n, rows - top - 1)        # core rows whose lower neighbour is present
    parts = [(weights[0], core[1:] - core[:-1]), (weights[1], xh[:, top + 1:top + 1 + below] - core[:, :below]),
             (weights[2], core[..., 1:] - core[..., :-1])]
    return float(sum(wd * np.abs(diff).sum(dtype=np.float64) for wd, diff in parts if wd > 0))


def tv_norm_blocks(x: np.ndarray, weights, workers: int) -> float:
    """Σ_d w_d Σ_i |x_{i+e_d} − x_i| of a (K, H, W) cube in float64, by row blocks over ``workers`` threads."""
    k, h, w = x.shape

    def block(y0, y1, _scratch):
        top, bottom = halo(h, y0, y1)
        return tv_block_norm(x[:, y0 - top:y1 + bottom], top, y1 - y0, weights)

    return float(sum(map_blocks(block, h, k * w * x.itemsize, workers)))


def subspace_tv_blocks(c: np.ndarray, basis: np.ndarray, tau: float, weights, out: np.ndarray, workers: int):
    """out = Bᵀ·max(0, haar_tv(B·c)) block by block: a block's coefficients (with halo rows) are expanded
    to its K bands, stepped, clipped at 0 and projected, all in cache. ``out`` must not alias ``c``."""
    limits, scale = haar_limits(tau, weights)
    r, h, w = c.shape
    basis = np.ascontiguousarray(basis, dtype=c.dtype)
    k = basis.shape[0]

    def block(y0, y1, scratch):
        top, bottom = halo(h, y0, y1)
        rows = y1 - y0 + top + bottom
        coefficients = buffer(scratch, "coefficients", (r, rows * w), c.dtype)
        coefficients.reshape(r, rows, w)[...] = c[:, y0 - top:y1 + bottom]
        expanded = buffer(scratch, "expanded", (k, rows * w), c.dtype)
        np.matmul(basis, coefficients, out=expanded)                          # v = B·c
        step = haar_block(expanded.reshape(k, rows, w), top, y1 - y0, limits, scale, scratch)
        np.clip(step, 0, None, out=step)
        projected = buffer(scratch, "projected", (r, (y1 - y0) * w), c.dtype)
        np.matmul(basis.T, step.reshape(k, -1), out=projected)                # c⁺ = Bᵀ·max(0, ·)
        out[:, y0:y1] = projected.reshape(r, y1 - y0, w)

    map_blocks(block, h, k * w * c.itemsize, workers)
    return out
