"""The OpenCL backend: the primitives of :class:`~clsdcam.backends.numpy.NumpyBackend`, same names,
signatures and ``out=`` semantics, on ``pyopencl.array.Array`` buffers.

Kernels live in ``kernels/*.cl`` (one program per context and dtype, built once); FFTs go through
:mod:`clsdcam.backends.fft` (pocketfft on mapped buffers for CPU devices, reikna or VkFFT on
GPUs). Launches are asynchronous on one in-order queue; data crosses to the host only in
``to_host`` and in the scalar reductions (``vdot``, ``amax``, norms, ``gram``).
"""
from __future__ import annotations

import sys

import numpy as np

from .cl_devices import (check_memory, choose_device, context_queue, describe, import_pyopencl,
                         problem_bytes, require_dtype)
from .numpy import COMPLEX_OF, real_dtype

try:
    import pyopencl as cl
    import pyopencl.array as cla

    from ..convolution import PrimitiveConvolution
    from .cl_convolution import READ, WRITE, MappedConvolution
    from .cl_program import Kernels
    from .fft import HostFFT, make_fft, mapped
    from .host_convolution import HostConvolution
    from .host_linalg import bandmix as host_bandmix
    from .host_linalg import gram as host_gram
    from .host_tv import subspace_tv_blocks, tv_norm_blocks
    _IMPORT_ERROR = None
except ImportError as _exc:  # no pyopencl: the constructor says how to install a driver
    cl = cla = None
    _IMPORT_ERROR = _exc

UNHELD_REFCOUNT = 3   # references to a buffer held only by HostBuffers: its list, the loop variable, getrefcount
GRAM_CHUNK = 4096     # pixels per gram work item (at least)
BANDMIX_TILE = 16     # pixels per bandmix work item (as in bandmix.cl)


class OpenCLBackend:
    """OpenCL primitives on one device (``device``: a name substring, a pyopencl Device, or None)."""

    name = "opencl"

    def __init__(self, dtype="float32", device=None, fft: str | None = None, kahan: bool | None = None,
                 host_kernels: bool | None = None):
        self.dtype = real_dtype(dtype)
        self.cdtype = COMPLEX_OF[self.dtype]
        if _IMPORT_ERROR is not None:
            import_pyopencl()          # raises InputError with the installation hint
            raise _IMPORT_ERROR
        self.device = device if isinstance(device, cl.Device) else choose_device(device)
        require_dtype(self.device, self.dtype)
        self.device_name = describe(self.device)
        self.context, self.queue = context_queue(self.device)
        self.kernels = Kernels(self.queue, self.dtype, kahan)
        self.allocator = HostBuffers(self.context) if self.device.type & cl.device_type.CPU else None
        self.fft = make_fft(self.queue, fft or "auto", self.dtype, self.kernels)
        self.fft_engine = self.fft.name
        self._band_cubes: dict = {}       # shape -> the band cubes of subspace_tv
        # CPU devices: subspace_tv, gram, bandmix and tv_norm run the host's code on mapped buffers (PoCL's
        # kernels are 1.3-25× slower there); the kernels serve every other device (both paths parity-tested)
        self.host_kernels = isinstance(self.fft, HostFFT) if host_kernels is None else host_kernels

    # ---- memory -------------------------------------------------------------------------
    def to_device(self, host, complex_: bool = False):
        """A device copy of ``host`` in the backend's (complex) dtype."""
        array = np.ascontiguousarray(host, dtype=self.cdtype if complex_ else self.dtype)
        return cla.to_device(self.queue, array, allocator=self.allocator)

    def to_host(self, array) -> np.ndarray:
        return self._drained(array.get(queue=self.queue))

    def empty(self, shape, complex_: bool = False):
        return cla.empty(self.queue, tuple(shape), self.cdtype if complex_ else self.dtype, allocator=self.allocator)

    def zeros(self, shape, complex_: bool = False):
        out = self.empty(shape, complex_)
        out.fill(0, queue=self.queue)
        return out

    def copy(self, x, out=None):
        out = self._out(out, x.shape, x.dtype)
        if x.nbytes:
            cl.enqueue_copy(self.queue, out.data, x.data, byte_count=x.nbytes)
        return out

    def estimate_bytes(self, sensor_shape, field_shape, n_bands: int) -> int:
        """Device memory one solve needs, in bytes (field cubes, spectrum, filters, FFT work)."""
        return problem_bytes(sensor_shape, field_shape, n_bands, self.dtype)[0]

    def check_memory(self, nbytes: int, largest: int = 0) -> None:
        """InputError (needed vs available MiB, and what to do) if the device cannot hold the problem."""
        check_memory(self.device, nbytes, largest)

    def check_problem(self, sensor_shape, field_shape, n_bands: int) -> None:
        """:meth:`check_memory` for one solve of this geometry."""
        check_memory(self.device, *problem_bytes(sensor_shape, field_shape, n_bands, self.dtype))

    # ---- FFT ----------------------------------------------------------------------------
    def fast_length(self, n: int) -> int:
        """The smallest length ≥ n the FFT engine transforms fast."""
        return self.fft.fast_length(n)

    def convolution(self, transfer, filters, field_shape, skip_unseen: bool = True):
        """A's filtered convolution: the host pipeline on mapped buffers with the host engine, else primitives."""
        if isinstance(self.fft, HostFFT):
            return MappedConvolution(self.queue, HostConvolution(transfer, filters, field_shape, self.dtype,
                                                                 self.fft.workers, skip_unseen))
        return PrimitiveConvolution(self, transfer, filters, field_shape)

    def fft2(self, x, out=None):
        """X = rfft2(x) over the last two axes: (..., Hp, Wp) real -> (..., Hp, Wp//2+1) complex."""
        out = self._out(out, x.shape[:-1] + (x.shape[-1] // 2 + 1,), self.cdtype)
        self.fft.forward(_stack(x), _stack(out))
        return out

    def ifft2(self, spectrum, shape, out=None):
        """x = irfft2(X, s=shape) over the last two axes."""
        shape = tuple(shape)
        if spectrum.shape[-1] != shape[-1] // 2 + 1 or spectrum.shape[-2] != shape[-2]:
            raise ValueError(f"spectrum {spectrum.shape} does not match a real field {shape}")
        out = self._out(out, spectrum.shape[:-2] + shape, self.dtype)
        self.fft.inverse(_stack(spectrum), _stack(out))
        return out

    def cmul(self, spectrum, transfer, conj: bool = False, out=None):
        """X·Ĥ (or X·conj(Ĥ)), Ĥ (Hp, Wp//2+1) broadcast over bands (out may alias X)."""
        out = self._out(out, spectrum.shape, self.cdtype)
        plane = transfer.size
        self.kernels.grid2("cmul", plane, spectrum.size // plane, out, spectrum, transfer,
                           np.int32(plane), np.int32(bool(conj)))
        return out

    # ---- geometry -----------------------------------------------------------------------
    def pad(self, x, field_shape, offset, out=None):
        """Zero field of ``field_shape`` (last two axes) with x placed at ``offset`` = (oy, ox)."""
        out = self._out(out, x.shape[:-2] + tuple(field_shape), x.dtype)
        self.kernels.grid3("pad", _planes(out), out, x, *_ints(*x.shape[-2:], *field_shape, *offset))
        return out

    def crop(self, x, shape, offset, out=None):
        """The ``shape`` window of x's last two axes starting at ``offset`` = (oy, ox)."""
        out = self._out(out, x.shape[:-2] + tuple(shape), x.dtype)
        self.kernels.grid3("crop", _planes(out), out, x, *_ints(*shape, *x.shape[-2:], *offset))
        return out

    def mask_sum(self, filters, field, offset, out=None):
        """b = Σ_k F_k ⊙ crop(field_k): (K,H,W) filters, (K,Hp,Wp) field -> (H,W)."""
        k, h, w = filters.shape
        out = self._out(out, (h, w), self.dtype)
        self.kernels.grid3("mask_sum", (1, h, w), out, filters, field,
                           *_ints(k, h, w, *field.shape[-2:], *offset))
        return out

    def mask_spread(self, filters, r, field_shape, offset, out=None):
        """v_k = pad(F_k ⊙ r): the adjoint of mask_sum; (H,W) -> (K,Hp,Wp), in one pass."""
        k, h, w = filters.shape
        out = self._out(out, (k,) + tuple(field_shape), self.dtype)
        self.kernels.grid3("mask_spread", out.shape, out, filters, r, *_ints(k, h, w, *field_shape, *offset))
        return out

    # ---- vectors ------------------------------------------------------------------------
    def scale(self, a, x, out=None):
        """a·x."""
        return self._map("scale", x, out, x, self._real(a))

    def axpy(self, a, x, y, out=None):
        """a·x + y (out may alias x or y)."""
        return self._map("axpy", x, out, self._real(a), x, y)

    def extrapolate(self, x_new, x_old, beta, out=None):
        """FISTA momentum: x⁺ + β(x⁺ − x)  (out may alias x_old)."""
        return self._map("extrapolate", x_new, out, x_new, x_old, self._real(beta))

    def vdot(self, x, y) -> float:
        """⟨x, y⟩, per-group partial sums in float64 (Kahan float32 without fp64), finished on the host."""
        return self._drained(_total(self.kernels.reduce("vdot", x.size, x, y)))

    def amax(self, x) -> float:
        """max |x|."""
        return self._drained(float(self.kernels.reduce("amax", x.size, x).max())) if x.size else 0.0

    def nonneg(self, x, out=None):
        """max(x, 0)."""
        return self._map("nonneg", x, out, x)

    def soft(self, x, t, out=None):
        """Soft threshold sign(x)·max(|x| − t, 0)."""
        return self._map("soft", x, out, x, self._real(t))

    def haar_tv(self, x, tau, weights, out=None, nonneg: bool = False):
        """One parallel-proximal Haar step for weighted anisotropic TV (see NumpyBackend.haar_tv), then
        max(·, 0) if ``nonneg``:

            out_i = x_i + 1/(2D) Σ_d [clip((x_{i+1} − x_i)/2, ±c_d) + clip((x_{i−1} − x_i)/2, ±c_d)],
            c_d = 2·D·τ·w_d over the D axes with w_d > 0; one kernel, one pass.
        """
        k, h, w = x.shape
        limits, mask, scale = self._haar_constants(tau, weights)
        target = self.empty(x.shape) if out is not None and _same_buffer(out, x) else self._out(out, x.shape, x.dtype)
        self.kernels.grid3("haar_tv", x.shape, target, x, *_ints(k, h, w), mask, *limits, scale, np.int32(bool(nonneg)))
        return self.copy(target, out) if target is not out and out is not None else target

    def tv_norm(self, x, weights) -> float:
        """Σ_d w_d Σ_i |x_{i+1} − x_i| along axis d (cube order λ, y, x), partial sums in float64 (on CPU
        devices the host's row blocks over the mapped cube)."""
        if self.host_kernels:
            with mapped(self.queue, x, READ) as host_x:
                return self._drained(tv_norm_blocks(host_x, weights, self.fft.workers))
        acc = self.kernels.acc.type
        w = [acc(wd if wd > 0 else 0.0) for wd in weights]
        return self._drained(_total(self.kernels.reduce("tv_norm", x.shape[0] * x.shape[1], x, *_ints(*x.shape), *w)))

    def fista_stats(self, x_new, x_old, y) -> tuple[float, float, float]:
        """(‖x⁺ − x‖², ‖x⁺‖², ⟨y − x⁺, x⁺ − x⟩) in one pass (differences in REAL, products in ACC)."""
        partials = self.kernels.reduce("fista_stats", x_new.size, x_new, x_old, y, outputs=3)
        return self._drained(tuple(_total(row) for row in partials))

    def l1_norm(self, x) -> float:
        return self._drained(_total(self.kernels.reduce("l1", x.size, x)))

    def gram(self, x) -> np.ndarray:
        """G = X Xᵀ (K×K, float64 on the host) of the bands×pixels unfolding X of x.

        Kernel: work item (j, i, g) sums x_i·x_j over pixel chunk g (j ≥ i) in float64; the host adds the chunks.
        """
        if self.host_kernels:
            with mapped(self.queue, x, READ) as host_x:
                return host_gram(host_x)
        k, pixels = x.shape[0], x.size // x.shape[0]
        groups = max(1, min(-(-pixels // GRAM_CHUNK), 4 * self.device.max_compute_units))
        chunk = -(-pixels // groups)
        partial = cla.empty(self.queue, (groups, k, k), self.kernels.acc)
        partial.fill(0, queue=self.queue)
        self.kernels.launch("gram", (k, k, groups), None, partial, x, np.int32(k), np.int64(pixels), np.int64(chunk))
        upper = np.triu(self.to_host(partial).sum(axis=0, dtype=np.float64))
        return upper + np.triu(upper, 1).T

    def bandmix(self, x, matrix, out=None):
        """out_k = Σ_j M_kj x_j: a K×J matrix (from the host) applied along the band axis of x (J bands)."""
        rows, cols = np.shape(matrix)
        shape = (rows,) + x.shape[1:]
        target = self.empty(shape) if out is not None and _same_buffer(out, x) else self._out(out, shape, x.dtype)
        if self.host_kernels:
            with mapped(self.queue, x, READ) as host_x, mapped(self.queue, target, WRITE) as host_out:
                host_bandmix(host_x, matrix, out=host_out)
        else:
            pixels = x.size // x.shape[0]
            m = cla.to_device(self.queue, np.ascontiguousarray(matrix, dtype=self.dtype))
            self.kernels.grid2("bandmix", -(-pixels // BANDMIX_TILE), rows, target, x, m, np.int32(cols),
                               np.int64(pixels))
        return self.copy(target, out) if target is not out and out is not None else target

    def subspace_tv(self, c, basis, tau, weights, out=None):
        """c⁺ = Bᵀ·max(0, haar_tv(B·c)) (see NumpyBackend.subspace_tv). On CPU devices, the host's cache-blocked
        code on the mapped buffers (at 64×576×800, r = 3: ~90 ms against ~145 ms for the kernels, which
        must write and read two band cubes); elsewhere, or with ``host_kernels=False``, the kernels:
        expand, the fused haar_tv, project."""
        target = self.empty(c.shape) if out is not None and _same_buffer(out, c) else self._out(out, c.shape, c.dtype)
        if self.host_kernels:
            with mapped(self.queue, c, READ) as host_c, mapped(self.queue, target, WRITE) as host_out:
                subspace_tv_blocks(host_c, basis, tau, weights, host_out, self.fft.workers)
        else:
            self._subspace_tv_kernels(c, basis, tau, weights, target)
        return self.copy(target, out) if target is not out and out is not None else target

    def _subspace_tv_kernels(self, c, basis, tau, weights, out):
        """Expand, haar_tv with max(·, 0), project, through band cubes kept per shape."""
        shape = (basis.shape[0],) + tuple(c.shape[1:])
        if shape not in self._band_cubes:
            self._band_cubes[shape] = (self.empty(shape), self.empty(shape))
        expanded, stepped = self._band_cubes[shape]
        self.bandmix(c, basis, out=expanded)
        self.haar_tv(expanded, tau, weights, out=stepped, nonneg=True)
        return self.bandmix(stepped, np.transpose(basis), out=out)

    def _haar_constants(self, tau, weights):
        """(clip bounds c_d = 2·D·τ·w_d per axis, bit mask of the active axes, 1/(2D)) in the kernels' types."""
        active = [wd > 0 for wd in weights]
        d = sum(active)
        limits = [self._real(2.0 * d * tau * wd if on else 0.0) for wd, on in zip(weights, active)]
        mask = np.int32(sum(1 << axis for axis, on in enumerate(active) if on))
        return limits, mask, self._real(1.0 / (2 * d) if d else 0.0)

    # ---- helpers ------------------------------------------------------------------------
    def _map(self, name: str, like, out, *args):
        """An elementwise kernel of fista.cl/prox.cl over ``like``'s elements: name(out, *args, n)."""
        out = self._out(out, like.shape, like.dtype)
        self.kernels.grid1(name, like.size, out, *args, np.int64(like.size))
        return out

    def _drained(self, value):
        """``value`` came from a blocking read: the queue is empty, host buffers nobody holds can go."""
        if self.allocator is not None:
            self.allocator.drained()
        return value

    def _out(self, out, shape, dtype):
        """``out`` after checking its shape and dtype, or a new array."""
        if out is None:
            return cla.empty(self.queue, tuple(shape), dtype, allocator=self.allocator)
        if tuple(out.shape) != tuple(shape) or out.dtype != dtype:
            raise ValueError(f"out {out.shape} {out.dtype}: expected {tuple(shape)} {np.dtype(dtype)}")
        return out

    def _real(self, value):
        return self.dtype.type(value)


class HostBuffers:
    """The allocator of CPU devices: USE_HOST_PTR buffers over NumPy memory, zero-copy on PoCL (128-byte
    aligned), with NumPy's transparent huge pages on large allocations, which made pocketfft's passes over
    mapped cubes 20–25 % faster than on PoCL's own ALLOC_HOST_PTR memory.

    The host memory is ours, not the driver's, so it must outlive the kernels queued on it: each buffer is
    held here too, and let go only at a sync point (:meth:`drained`, after a blocking read or map, when
    the in-order queue has finished everything enqueued before) once nobody else holds it.
    """

    FLAGS = cl.mem_flags.READ_WRITE | cl.mem_flags.USE_HOST_PTR if cl is not None else None

    def __init__(self, context):
        self.context = context
        self._held: list = []

    def __call__(self, nbytes: int):
        buffer = cl.Buffer(self.context, self.FLAGS, hostbuf=aligned_bytes(max(nbytes, 1)))
        self._held.append(buffer)
        return buffer

    def drained(self):
        """Everything enqueued so far has finished: release the buffers only this list still holds."""
        self._held = [buffer for buffer in self._held if sys.getrefcount(buffer) > UNHELD_REFCOUNT]

    def __len__(self):
        return len(self._held)


def aligned_bytes(nbytes: int, alignment: int = 128) -> np.ndarray:
    """``nbytes`` of NumPy memory starting on an ``alignment``-byte boundary."""
    raw = np.empty(nbytes + alignment, np.uint8)
    start = -raw.ctypes.data % alignment
    return raw[start:start + nbytes]


def _ints(*values) -> list:
    return [np.int32(v) for v in values]


def _planes(x) -> tuple[int, int, int]:
    """(B, H, W) of an array whose leading axes are flattened into B."""
    return (int(np.prod(x.shape[:-2], dtype=np.int64)),) + tuple(x.shape[-2:])


def _stack(x):
    """x viewed as (B, H, W) (same buffer)."""
    return x if x.ndim == 3 else x.reshape(_planes(x))


def _same_buffer(a, b) -> bool:
    return a.base_data == b.base_data


def _total(partials: np.ndarray) -> float:
    return float(np.sum(partials, dtype=np.float64))
