"""The OpenCL backend: the contract of ``base.py`` (Math, Platform, Fusions) on ``pyopencl.array.Array`` buffers.

Kernels live in ``kernels/*.cl`` (one program per context and dtype, built once); FFTs go through
:mod:`clsdcam.backends.fft`. Which code runs the heavy primitives is the path's (``base.py``), resolved once in
the constructor, which picks the path's code object (:data:`PATH_CODE`): on the host path (CPU devices) A and
the ``HOST_CODE`` primitives run host code on mapped buffers (``cl_host.MappedHostCode``), on the device path
kernels (``cl_kernel_code.KernelCode``); the backend's methods of those names call it. Everything else is a
kernel on both paths. Launches are asynchronous on one in-order queue; data crosses to the host only in
``to_host``, in host views and in the scalar reductions (``vdot``, ``amax``, norms, ``gram``).
"""
from __future__ import annotations

import numpy as np

from .base import ints, resolve_path, total
from .cl_devices import (check_memory, check_problem, choose_device, context_queue, describe, import_pyopencl, is_cpu,
                         require_dtype)
from .numpy import COMPLEX_OF, real_dtype

try:
    import pyopencl as cl
    import pyopencl.array as cla

    from .cl_host import MappedHostCode
    from .cl_kernel_code import KernelCode
    from .cl_memory import HostBuffers, mapped
    from .cl_program import Kernels
    from .fft import make_fft
    PATH_CODE = {"host": MappedHostCode, "device": KernelCode}     # a path's code for A and the HOST_CODE primitives
    _IMPORT_ERROR = None
except ImportError as _exc:  # no pyopencl: the constructor says how to install a driver
    cl = cla = PATH_CODE = None
    _IMPORT_ERROR = _exc


class OpenCLBackend:
    """OpenCL primitives on one device (``device``: a name substring, a pyopencl Device, or None; ``path`` and
    ``fft`` as in ``base.py``; ``kahan`` forces compensated float32 sums)."""

    name = "opencl"

    def __init__(self, dtype="float32", device=None, fft: str = "auto", path: str = "auto", kahan: bool | None = None):
        self.dtype = real_dtype(dtype)
        self.cdtype = COMPLEX_OF[self.dtype]
        if _IMPORT_ERROR is not None:
            import_pyopencl()          # raises InputError with the installation hint
            raise _IMPORT_ERROR
        self.device = device if isinstance(device, cl.Device) else choose_device(device)
        require_dtype(self.device, self.dtype)
        self.device_name = describe(self.device)
        self.context, self.queue = context_queue(self.device)
        cpu = is_cpu(self.device)
        self.path = resolve_path(path, cpu)           # the host/device choice, made here once
        self.kernels = Kernels(self.queue, self.dtype, kahan)
        self.allocator = HostBuffers(self.queue) if cpu else None
        self.fft = make_fft(self.queue, self.path, fft, self.dtype, self.kernels)
        self.fft_engine = self.fft.name
        self.workers = getattr(self.fft, "workers", 1)
        self.code = PATH_CODE[self.path](self)        # the path's A and HOST_CODE primitives

    # ---- memory -------------------------------------------------------------------------
    def to_device(self, host, complex_: bool = False):
        array = np.ascontiguousarray(host, dtype=self.cdtype if complex_ else self.dtype)
        return cla.to_device(self.queue, array, allocator=self.allocator)

    def to_host(self, array) -> np.ndarray:
        return self.drained(array.get(queue=self.queue))

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

    def host_view(self, array, mode: str):
        """The array mapped into host memory (zero-copy on CPU devices)."""
        return mapped(self.queue, array, mode)

    def check_memory(self, nbytes: int, largest: int = 0) -> None:
        """InputError (needed vs available MiB, and what to do) if the device cannot hold ``nbytes``."""
        check_memory(self.device, nbytes, largest)

    def check_problem(self, sensor_shape, field_shape, n_bands: int, field_buffers: int | None = None) -> None:
        check_problem(self.device, sensor_shape, field_shape, n_bands, self.dtype, field_buffers)

    # ---- FFT ----------------------------------------------------------------------------
    def fast_length(self, n: int) -> int:
        return self.fft.fast_length(n)

    def fft2(self, x, out=None):
        out = self._out(out, x.shape[:-1] + (x.shape[-1] // 2 + 1,), self.cdtype)
        self.fft.forward(_stack(x), _stack(out))
        return out

    def ifft2(self, spectrum, shape, out=None):
        shape = tuple(shape)
        if spectrum.shape[-1] != shape[-1] // 2 + 1 or spectrum.shape[-2] != shape[-2]:
            raise ValueError(f"spectrum {spectrum.shape} does not match a real field {shape}")
        out = self._out(out, spectrum.shape[:-2] + shape, self.dtype)
        self.fft.inverse(_stack(spectrum), _stack(out))
        return out

    def convolution(self, transfer, filters, field_shape, skip_unseen: bool = True):
        """The path's (``base.Math.convolution``): the host pipeline on mapped buffers, or kernels."""
        return self.code.convolution(transfer, filters, field_shape, skip_unseen)

    def cmul(self, spectrum, transfer, conj: bool = False, out=None):
        out = self._out(out, spectrum.shape, self.cdtype)
        plane = transfer.size
        self.kernels.grid2("cmul", plane, spectrum.size // plane, out, spectrum, transfer,
                           np.int32(plane), np.int32(bool(conj)))
        return out

    # ---- geometry -----------------------------------------------------------------------
    def pad(self, x, field_shape, offset, out=None):
        out = self._out(out, x.shape[:-2] + tuple(field_shape), x.dtype)
        self.kernels.grid3("pad", _planes(out), out, x, *ints(*x.shape[-2:], *field_shape, *offset))
        return out

    def crop(self, x, shape, offset, out=None):
        out = self._out(out, x.shape[:-2] + tuple(shape), x.dtype)
        self.kernels.grid3("crop", _planes(out), out, x, *ints(*shape, *x.shape[-2:], *offset))
        return out

    def mask_sum(self, filters, field, offset, out=None):
        k, h, w = filters.shape
        out = self._out(out, (h, w), self.dtype)
        self.kernels.grid3("mask_sum", (1, h, w), out, filters, field,
                           *ints(k, h, w, *field.shape[-2:], *offset))
        return out

    def mask_spread(self, filters, r, field_shape, offset, out=None):
        """In one pass over the field (the padding written as zeros by the same kernel)."""
        k, h, w = filters.shape
        out = self._out(out, (k,) + tuple(field_shape), self.dtype)
        self.kernels.grid3("mask_spread", out.shape, out, filters, r, *ints(k, h, w, *field_shape, *offset))
        return out

    # ---- vectors ------------------------------------------------------------------------
    def scale(self, a, x, out=None):
        return self._map("scale", x, out, x, self._real(a))

    def axpy(self, a, x, y, out=None):
        return self._map("axpy", x, out, self._real(a), x, y)

    def extrapolate(self, x_new, x_old, beta, out=None):
        return self._map("extrapolate", x_new, out, x_new, x_old, self._real(beta))

    def vdot(self, x, y) -> float:
        """Per-group partial sums in float64 (Kahan float32 without fp64), finished on the host."""
        return self.drained(total(self.kernels.reduce("vdot", x.size, x, y)))

    def amax(self, x) -> float:
        return self.drained(float(self.kernels.reduce("amax", x.size, x).max())) if x.size else 0.0

    def nonneg(self, x, out=None):
        return self._map("nonneg", x, out, x)

    def soft(self, x, t, out=None):
        return self._map("soft", x, out, x, self._real(t))

    def l1_norm(self, x) -> float:
        return self.drained(total(self.kernels.reduce("l1", x.size, x)))

    def fista_stats(self, x_new, x_old, y) -> tuple[float, float, float]:
        """One pass: differences in REAL, products in ACC."""
        partials = self.kernels.reduce("fista_stats", x_new.size, x_new, x_old, y, outputs=3)
        return self.drained(tuple(total(row) for row in partials))

    # ---- priors -------------------------------------------------------------------------
    def haar_tv(self, x, tau, weights, out=None, nonneg: bool = False):
        """One kernel, one pass (clip bounds c_d = 2·D·τ·w_d, see ``base.Math.haar_tv``)."""
        k, h, w = x.shape
        limits, mask, scale = self._haar_constants(tau, weights)
        target = self.target(out, x.shape, x)
        self.kernels.grid3("haar_tv", x.shape, target, x, *ints(k, h, w), mask, *limits, scale, np.int32(bool(nonneg)))
        return self.deliver(target, out)

    # ---- the path's code (``self.code``: host code on mapped buffers, or kernels) -------------
    def tv_norm(self, x, weights) -> float:
        return self.code.tv_norm(x, weights)

    def gram(self, x) -> np.ndarray:
        return self.code.gram(x)

    def bandmix(self, x, matrix, out=None):
        return self.code.bandmix(x, matrix, out)

    def subspace_tv(self, c, basis, tau, weights, out=None):
        return self.code.subspace_tv(c, basis, tau, weights, out)

    # ---- helpers ------------------------------------------------------------------------
    def target(self, out, shape, source):
        """Where a primitive reading ``source`` writes: ``out`` (checked), a new array when there is none or
        when ``out`` shares ``source``'s buffer (the kernels do not work in place)."""
        if out is not None and out.base_data == source.base_data:
            return self.empty(shape)
        return self._out(out, shape, source.dtype)

    def deliver(self, target, out):
        """The result of a primitive that wrote ``target``: copied into ``out`` when they differ."""
        return self.copy(target, out) if out is not None and target is not out else target

    def _haar_constants(self, tau, weights):
        """(clip bounds c_d = 2·D·τ·w_d per axis, bit mask of the active axes, 1/(2D)) in the kernels' types."""
        active = [wd > 0 for wd in weights]
        d = sum(active)
        limits = [self._real(2.0 * d * tau * wd if on else 0.0) for wd, on in zip(weights, active)]
        mask = np.int32(sum(1 << axis for axis, on in enumerate(active) if on))
        return limits, mask, self._real(1.0 / (2 * d) if d else 0.0)

    def _map(self, name: str, like, out, *args):
        """An elementwise kernel of fista.cl/prox.cl over ``like``'s elements: name(out, *args, n)."""
        out = self._out(out, like.shape, like.dtype)
        self.kernels.grid1(name, like.size, out, *args, np.int64(like.size))
        return out

    def drained(self, value):
        """``value`` came from a blocking read: the queue has finished what came before; retired host memory
        can go."""
        if self.allocator is not None:
            self.allocator.release_finished()
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


def _planes(x) -> tuple[int, int, int]:
    """(B, H, W) of an array whose leading axes are flattened into B."""
    return (int(np.prod(x.shape[:-2], dtype=np.int64)),) + tuple(x.shape[-2:])


def _stack(x):
    """x viewed as (B, H, W) (same buffer)."""
    return x if x.ndim == 3 else x.reshape(_planes(x))
