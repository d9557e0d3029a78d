"""Real 2-D FFTs of device arrays over their last two axes, batched over bands.

One interface, :class:`RealFFT`:

    forward(x, out)   x (K, Hp, Wp) real     -> out (K, Hp, Wp//2+1) complex  (= rfft2)
    inverse(X, out)   X (K, Hp, Wp//2+1)     -> out (K, Hp, Wp) real          (= irfft2, 1/N normalised)

Engines (``make_fft(queue, engine)``):

* ``host``   pocketfft (scipy.fft) on the host, on buffers mapped with ``enqueue_map_buffer``;
  zero-copy on CPU devices, whose arrays the backend allocates with ALLOC_HOST_PTR.
* ``reikna`` reikna's complex FFT on the device plus our ``fft.cl`` kernels: two real bands
  packed into one complex transform, z = x_a + i·x_b, unpacked by Hermitian symmetry
  X_a = (Z[κ] + conj Z[−κ])/2, X_b = (Z[κ] − conj Z[−κ])/(2i) (``pack=False``: one band each).
* ``vkfft``  pyvkfft's native R2C/C2R, when pyvkfft is installed.

``auto`` = host on CPU devices, vkfft on other devices when importable, else reikna.
Plans are built on first use for a shape and cached per (context, shape, dtype).
Each engine says which lengths it transforms fast (``fast_length``): 5-smooth for pocketfft's
real transforms, 7-smooth for VkFFT, powers of two for reikna (radix 2 only; any other length
goes through Bluestein's algorithm at a multiple of the cost).
"""
from __future__ import annotations

import atexit
import os
from contextlib import contextmanager

import numpy as np
import pyopencl as cl
import pyopencl.array as cla
import scipy.fft

from ..errors import InputError
from .cl_program import Kernels

ENGINES = ("auto", "host", "reikna", "vkfft")
_PLANS: dict = {}       # (engine, context, shape, dtype) -> plan
_THREADS: dict = {}     # queue -> reikna Thread


@atexit.register
def _release_plans():
    """Free cached plans while modules are still alive (reikna's finalisers fail at interpreter teardown)."""
    _PLANS.clear()
    _THREADS.clear()


class RealFFT:
    """rfft2 / irfft2 over the last two axes of (K, Hp, Wp) device arrays."""

    name = "?"

    def __init__(self, kernels: Kernels):
        self.kernels = kernels
        self.queue = kernels.queue

    def forward(self, x, out):
        raise NotImplementedError

    def inverse(self, spectrum, out):
        raise NotImplementedError

    def fast_length(self, n: int) -> int:
        """The smallest length ≥ n this engine transforms fast."""
        raise NotImplementedError


def smooth_length(n: int, primes=(2, 3, 5, 7)) -> int:
    """The smallest m ≥ n whose prime factors are all in ``primes``."""
    m = max(int(n), 1)
    while True:
        rest = m
        for p in primes:
            while rest % p == 0:
                rest //= p
        if rest == 1:
            return m
        m += 1


# ---- host (pocketfft on mapped buffers) -------------------------------------------------------

@contextmanager
def mapped(queue, array, flags):
    """The host view of a device array for the duration of the block (waits for queued work)."""
    host, _ = cl.enqueue_map_buffer(queue, array.base_data, flags, array.offset, array.shape, array.dtype)
    try:
        yield host
    finally:
        host.base.release(queue)


class HostFFT(RealFFT):
    """scipy.fft (pocketfft, ``workers`` threads) on mapped device buffers: for CPU devices."""

    name = "host"

    def __init__(self, kernels: Kernels, workers: int | None = None):
        super().__init__(kernels)
        self.workers = workers or os.cpu_count() or 1

    def fast_length(self, n: int) -> int:
        return scipy.fft.next_fast_len(int(n), real=True)

    def forward(self, x, out):
        with mapped(self.queue, x, cl.map_flags.READ) as src, \
                mapped(self.queue, out, cl.map_flags.WRITE_INVALIDATE_REGION) as dst:
            dst[...] = scipy.fft.rfft2(src, workers=self.workers)
        return out

    def inverse(self, spectrum, out):
        with mapped(self.queue, spectrum, cl.map_flags.READ) as src, \
                mapped(self.queue, out, cl.map_flags.WRITE_INVALIDATE_REGION) as dst:
            dst[...] = scipy.fft.irfft2(src, s=out.shape[-2:], workers=self.workers)
        return out


# ---- reikna (complex FFT + packing kernels) ---------------------------------------------------

class ReiknaFFT(RealFFT):
    """reikna's complex FFT over axes (1, 2) of P = ceil(K/m) packed complex fields (m = 2 if ``pack``)."""

    name = "reikna"

    def __init__(self, kernels: Kernels, pack: bool = True):
        super().__init__(kernels)
        self.per_transform = 2 if pack else 1
        self.cdtype = np.result_type(kernels.dtype, np.complex64)

    def fast_length(self, n: int) -> int:
        return smooth_length(n, (2,))

    def _plan(self, field_shape):
        """(compiled FFT, complex work array (P, Hp, Wp)) for a (K, Hp, Wp) field, built once."""
        k, hp, wp = field_shape
        shape = (-(-k // self.per_transform), hp, wp)
        key = ("reikna", self.queue.context, shape, self.cdtype)
        if key not in _PLANS:
            from reikna.core import Type
            from reikna.fft import FFT

            thread = reikna_thread(self.queue)
            compiled = FFT(Type(self.cdtype, shape=shape), axes=(1, 2)).compile(thread)
            _PLANS[key] = (compiled, cla.empty(self.queue, shape, self.cdtype))
        return _PLANS[key]

    def forward(self, x, out):
        k, hp, wp = x.shape
        fft, z = self._plan(x.shape)
        m, kern = np.int32(self.per_transform), self.kernels
        kern.grid3("fft_embed", z.shape, z, x, np.int32(k), m, np.int32(hp), np.int32(wp))
        fft(z, z, inverse=0)
        kern.grid3("fft_half", out.shape, out, z, np.int32(k), m, np.int32(hp), np.int32(wp), np.int32(out.shape[-1]))
        return out

    def inverse(self, spectrum, out):
        k, hp, wp = out.shape
        fft, z = self._plan(out.shape)
        m, kern = np.int32(self.per_transform), self.kernels
        dims = (np.int32(hp), np.int32(wp))
        kern.grid3("fft_full", z.shape, z, spectrum, np.int32(k), m, *dims, np.int32(spectrum.shape[-1]))
        fft(z, z, inverse=1)
        kern.grid3("fft_real", z.shape, out, z, np.int32(k), m, *dims)
        return out


def reikna_thread(queue):
    """One reikna Thread wrapping our queue (cached)."""
    if queue not in _THREADS:
        from reikna.cluda import ocl_api

        _THREADS[queue] = ocl_api().Thread(queue)
    return _THREADS[queue]


# ---- VkFFT (optional) -------------------------------------------------------------------------

class VkFFT(RealFFT):
    """pyvkfft's out-of-place R2C / C2R (normalised like numpy); note C2R may overwrite its input."""

    name = "vkfft"

    def fast_length(self, n: int) -> int:
        return smooth_length(n, (2, 3, 5, 7))

    def _app(self, real_shape):
        key = ("vkfft", self.queue.context, tuple(real_shape), self.kernels.dtype)
        if key not in _PLANS:
            from pyvkfft.opencl import VkFFTApp

            _PLANS[key] = VkFFTApp(tuple(real_shape), self.kernels.dtype, queue=self.queue, ndim=2,
                                   r2c=True, inplace=False, norm=1)
        return _PLANS[key]

    def forward(self, x, out):
        self._app(x.shape).fft(x, out)
        return out

    def inverse(self, spectrum, out):
        self._app(out.shape).ifft(spectrum, out)
        return out


def vkfft_available() -> bool:
    try:
        import pyvkfft.opencl  # noqa: F401
    except Exception:  # noqa: BLE001 - any import failure means "not available"
        return False
    return True


def available_engines(device) -> list[str]:
    """The engines usable on ``device`` (host and reikna always; vkfft when installed)."""
    return ["host", "reikna"] + (["vkfft"] if vkfft_available() else [])


def resolve_engine(device, engine: str = "auto") -> str:
    """``auto`` -> host on CPU devices, vkfft if installed, else reikna; other names are checked."""
    if engine not in ENGINES:
        raise InputError(f"FFT engine {engine!r}: expected one of {', '.join(ENGINES)}")
    if engine == "auto":
        if device.type & cl.device_type.CPU:
            return "host"
        return "vkfft" if vkfft_available() else "reikna"
    if engine == "vkfft" and not vkfft_available():
        raise InputError("FFT engine 'vkfft' needs pyvkfft (pip install pyvkfft)")
    return engine


def make_fft(queue, engine: str = "auto", dtype="float32", kernels: Kernels | None = None) -> RealFFT:
    """The FFT engine on ``queue`` for ``dtype`` (``engine`` as in :func:`resolve_engine`; its ``name`` says which)."""
    kernels = kernels or Kernels(queue, dtype)
    name = resolve_engine(queue.device, engine)
    if name == "host":
        return HostFFT(kernels)
    if name == "vkfft":
        return VkFFT(kernels)
    return ReiknaFFT(kernels, pack=True)
