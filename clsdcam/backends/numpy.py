"""The NumPy/SciPy reference primitives: readable first, every OpenCL kernel is checked against them.

The contract (what each primitive computes, layouts, ``out=``) is ``base.py``'s (``Math``, ``Platform`` and the
optional ``Fusions``, all kept here); the docstrings here say only how NumPy computes it. Always the host path:
the heavy primitives run cache-blocked on row blocks over a few threads (``host_tv``, ``blocks``), BLAS
(``host_linalg``) and pocketfft; A is the chunked pocketfft pipeline (``convolution.host_path``).
"""
from __future__ import annotations

from contextlib import nullcontext

import numpy as np
import scipy.fft

from ..errors import InputError
from . import host_linalg
from .blocks import host_threads, map_blocks, scratch_buffer
from .convolution import host_path
from .host_tv import haar_block, haar_limits, halo, subspace_tv_blocks, tv_norm_blocks

VDOT_ROW = 8192   # products per float32 partial sum in vdot
COMPLEX_OF = {np.dtype(np.float32): np.dtype(np.complex64), np.dtype(np.float64): np.dtype(np.complex128)}


def real_dtype(dtype) -> np.dtype:
    """float32 or float64, or InputError naming the value."""
    try:
        dt = np.dtype(dtype)
    except TypeError as exc:
        raise InputError(f"--dtype {dtype!r}: expected float32 or float64") from exc
    if dt not in COMPLEX_OF:
        raise InputError(f"--dtype {dtype!r}: expected float32 or float64")
    return dt


def _result(out, value):
    """Write ``value`` into ``out`` (if given) and return the array holding it."""
    if out is None:
        return value
    out[...] = value
    return out


class NumpyBackend:
    """Host reference backend (NumPy + SciPy's pocketfft)."""

    name = "numpy"
    path = "host"

    def __init__(self, dtype="float32", workers: int | None = None):
        self.dtype = real_dtype(dtype)
        self.cdtype = COMPLEX_OF[self.dtype]
        self.workers = workers or host_threads()
        self.device_name = "host CPU (NumPy/SciPy)"
        self.fft_engine = "scipy pocketfft"

    # ---- memory -------------------------------------------------------------------------
    def to_device(self, host: np.ndarray, complex_: bool = False) -> np.ndarray:
        return np.array(host, dtype=self.cdtype if complex_ else self.dtype, order="C", copy=True)

    def to_host(self, array: np.ndarray) -> np.ndarray:
        return np.array(array, copy=True)

    def empty(self, shape, complex_: bool = False) -> np.ndarray:
        return np.empty(shape, self.cdtype if complex_ else self.dtype)

    def zeros(self, shape, complex_: bool = False) -> np.ndarray:
        return np.zeros(shape, self.cdtype if complex_ else self.dtype)

    def copy(self, x, out=None):
        return _result(out, x) if out is not None else x.copy()

    def host_view(self, array: np.ndarray, mode: str):
        """The array itself."""
        return nullcontext(array)

    def check_problem(self, sensor_shape, field_shape, n_bands: int, field_buffers: int | None = None) -> None:
        """Host memory is not checked ahead (NumPy raises MemoryError where it runs out)."""

    # ---- FFT ----------------------------------------------------------------------------
    def fast_length(self, n: int) -> int:
        """The smallest length ≥ n that pocketfft transforms fast (5-smooth for real transforms)."""
        return scipy.fft.next_fast_len(int(n), real=True)

    def fft2(self, x, out=None):
        return _result(out, scipy.fft.rfft2(x, workers=self.workers))

    def ifft2(self, spectrum, shape, out=None):
        return _result(out, scipy.fft.irfft2(spectrum, s=shape, workers=self.workers))

    def convolution(self, transfer, filters, field_shape, skip_unseen: bool = True):
        """The host path's: the chunked pocketfft pipeline on the arrays themselves."""
        return host_path(self, transfer, filters, field_shape, skip_unseen)

    def cmul(self, spectrum, transfer, conj: bool = False, out=None):
        factor = np.conj(transfer) if conj else transfer
        if out is None:
            return spectrum * factor
        np.multiply(spectrum, factor, out=out)
        return out

    # ---- geometry -----------------------------------------------------------------------
    def pad(self, x, field_shape, offset, out=None):
        if out is None:
            out = np.zeros(x.shape[:-2] + tuple(field_shape), x.dtype)
        else:
            out[...] = 0
        oy, ox = offset
        out[..., oy:oy + x.shape[-2], ox:ox + x.shape[-1]] = x
        return out

    def crop(self, x, shape, offset, out=None):
        oy, ox = offset
        return _result(out, x[..., oy:oy + shape[0], ox:ox + shape[1]].copy())

    def mask_sum(self, filters, field, offset, out=None):
        oy, ox = offset
        window = field[:, oy:oy + filters.shape[-2], ox:ox + filters.shape[-1]]
        return np.einsum("khw,khw->hw", filters, window, out=out)

    def mask_spread(self, filters, r, field_shape, offset, out=None):
        return self.pad(filters * r, field_shape, offset, out=out)

    # ---- vectors ------------------------------------------------------------------------
    def scale(self, a, x, out=None):
        return np.multiply(x, a, out=out) if out is not None else a * x

    def axpy(self, a, x, y, out=None):
        if out is None:
            return a * x + y
        if out is y:
            out += x if a == 1 else a * x          # no temporary cube when a = 1
            return out
        np.multiply(x, a, out=out)
        out += y
        return out

    def extrapolate(self, x_new, x_old, beta, out=None):
        """Row blocks in parallel."""
        if out is None:
            out = np.empty_like(x_new)
        new, old, target = (_as_rows(a) for a in (x_new, x_old, out))

        def block(y0, y1, _scratch):
            rows = target[:, y0:y1]
            np.subtract(new[:, y0:y1], old[:, y0:y1], out=rows)
            rows *= beta
            rows += new[:, y0:y1]

        map_blocks(block, new.shape[1], new.shape[0] * new.shape[2] * new.itemsize, self.workers)
        return out

    def vdot(self, x, y) -> float:
        """Rows of VDOT_ROW products summed by einsum in the array's dtype (SIMD partial sums),
        the row sums added in float64 — 5× faster than a float64 copy, ~1e-8 relative over 10⁸
        float32 terms (tests/stress)."""
        a, b = np.ravel(x), np.ravel(y)
        whole = a.size - a.size % VDOT_ROW
        rows = np.einsum("ij,ij->i", a[:whole].reshape(-1, VDOT_ROW), b[:whole].reshape(-1, VDOT_ROW))
        return float(rows.sum(dtype=np.float64) + np.dot(a[whole:].astype(np.float64), b[whole:].astype(np.float64)))

    def amax(self, x) -> float:
        return float(np.max(np.abs(x)))

    def nonneg(self, x, out=None):
        return np.maximum(x, 0, out=out)

    def soft(self, x, t, out=None):
        return _result(out, np.sign(x) * np.maximum(np.abs(x) - t, 0))

    def haar_tv(self, x, tau, weights, out=None, nonneg: bool = False):
        """Computed on cache-sized row blocks in parallel (backends/host_tv.py)."""
        limits, scale = haar_limits(tau, weights)
        k, h, w = x.shape
        target = out if out is not None and not np.shares_memory(out, x) else np.empty_like(x)

        def block(y0, y1, scratch):
            top, bottom = halo(h, y0, y1)
            step = haar_block(x[:, y0 - top:y1 + bottom], top, y1 - y0, limits, scale, scratch)
            if nonneg:
                np.clip(step, 0, None, out=target[:, y0:y1])
            else:
                target[:, y0:y1] = step

        map_blocks(block, h, k * w * x.itemsize, self.workers)
        return _result(out, target) if target is not out else out

    def tv_norm(self, x, weights) -> float:
        """By row blocks in parallel (backends/host_tv.py)."""
        return tv_norm_blocks(x, weights, self.workers)

    def fista_stats(self, x_new, x_old, y) -> tuple[float, float, float]:
        """One pass over row blocks in parallel."""
        new, old, ahead = (_as_rows(a) for a in (x_new, x_old, y))

        def block(y0, y1, scratch):
            current = new[:, y0:y1]
            step = np.subtract(current, old[:, y0:y1], out=scratch_buffer(scratch, "step", current.shape, current.dtype))   # x⁺ − x
            back = np.subtract(ahead[:, y0:y1], current, out=scratch_buffer(scratch, "back", current.shape, current.dtype))  # y − x⁺
            return _row_dot(step, step), _row_dot(current, current), _row_dot(back, step)

        parts = map_blocks(block, new.shape[1], new.shape[0] * new.shape[2] * new.itemsize, self.workers)
        return tuple(float(np.sum([p[i] for p in parts], dtype=np.float64)) for i in range(3))

    def l1_norm(self, x) -> float:
        return float(np.sum(np.abs(x), dtype=np.float64))

    def gram(self, x) -> np.ndarray:
        """float64 sums of BLAS chunks (backends/host_linalg.py)."""
        return host_linalg.gram(x)

    def bandmix(self, x, matrix, out=None):
        """Written straight into ``out`` when it is a C-contiguous array of the result's shape and x's dtype not
        sharing x's memory."""
        shape = (np.shape(matrix)[0],) + x.shape[1:]
        if (out is not None and out.shape == shape and out.flags.c_contiguous and out.dtype == x.dtype
                and not np.shares_memory(out, x)):
            return host_linalg.bandmix(x, matrix, out=out)
        return _result(out, host_linalg.bandmix(x, matrix))

    def subspace_tv(self, c, basis, tau, weights, out=None):
        """On row blocks: each block's K-band expansion lives only in cache (backends/host_tv.py)."""
        target = out if out is not None and not np.shares_memory(out, c) else np.empty_like(c)
        subspace_tv_blocks(c, basis, tau, weights, target, self.workers)
        return _result(out, target) if target is not out else out


def _as_rows(a: np.ndarray) -> np.ndarray:
    """A view of ``a`` as (planes, rows, columns): (K, H, W) as it is, lower ranks with leading 1s."""
    return a.reshape((1,) * (3 - a.ndim) + a.shape) if a.ndim < 3 else a.reshape(a.shape[0], a.shape[1], -1)


def _row_dot(a: np.ndarray, b: np.ndarray) -> float:
    """⟨a, b⟩ of two (P, R, C) blocks: float32 sums along each row's C products, the rows added in float64."""
    return float(np.einsum("ijk,ijk->ij", a, b).sum(dtype=np.float64))
