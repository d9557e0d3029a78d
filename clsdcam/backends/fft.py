"""Real 2-D FFTs of device arrays over their last two axes, batched over bands.

One interface, :class:`RealFFT`:

    forward(x, out)   x (K, Hp, Wp) real     -> out (K, Hp, Wp//2+1) complex  (= rfft2)
    inverse(X, out)   X (K, Hp, Wp//2+1)     -> out (K, Hp, Wp) real          (= irfft2, 1/N normalised)

Engines (``make_fft(queue, path, engine)``; which path runs which engine is the rule of ``base.py``):

* ``host``   pocketfft (scipy.fft) on the host, on mapped buffers (the host path: zero-copy on CPU
  devices, whose buffers the backend allocates over NumPy memory, see ``cl_memory``).
* ``reikna`` reikna's complex FFT on the device plus our ``fft.cl`` kernels: two real bands
  packed into one complex transform, z = x_a + i·x_b, unpacked by Hermitian symmetry
  X_a = (Z[κ] + conj Z[−κ])/2, X_b = (Z[κ] − conj Z[−κ])/(2i) (``pack=False``: one band each).
* ``vkfft``  pyvkfft's native R2C/C2R, when pyvkfft is installed, for 7-smooth planes; a plane with a
  prime factor above 7 goes to reikna (VkFFT builds those with Rader's algorithm, and on Intel's CPU
  runtime about one such plan in three transforms wrong: ``docs/portability.md``). The support field
  (``--support-field``) is 7-smooth (``fast_length``); the paper's 2H × 2W (the default's and ``--no-skip``'s)
  is not when H or W has a prime factor above 7, and is a power of two for reikna only when H and W are.

Plans are built on first use for a shape and kept in bounded caches (the few most recent).
Each engine says which lengths it transforms fast (``fast_length``): 5-smooth for pocketfft's
real transforms, 7-smooth for VkFFT, powers of two for reikna (radix 2 only; any other length
goes through Bluestein's algorithm at a multiple of the cost).
"""
from __future__ import annotations

import atexit
from functools import lru_cache

import numpy as np
import pyopencl.array as cla
import scipy.fft

from ..errors import InputError
from .base import DEVICE_ENGINES, check_engine
from .blocks import host_threads
from .cl_memory import mapped
from .cl_program import Kernels

PLAN_CACHE = 8          # FFT plans kept (per engine), the most recently used
VKFFT_PRIMES = (2, 3, 5, 7)     # the prime factors VkFFT's plans may have here (no Rader's algorithm)


@atexit.register
def _release_plans():
    """Free cached plans while modules are still alive (reikna's finalisers fail at interpreter teardown)."""
    for cached in (_reikna_plan, _vkfft_app, reikna_thread):
        cached.cache_clear()


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

class HostFFT(RealFFT):
    """scipy.fft (pocketfft, ``workers`` threads) on mapped device buffers: for CPU devices."""

    name = "host"

    def __init__(self, kernels: Kernels, workers: int | None = None):
        super().__init__(kernels)
        self.workers = workers or host_threads()

    def fast_length(self, n: int) -> int:
        return scipy.fft.next_fast_len(int(n), real=True)

    def forward(self, x, out):
        with mapped(self.queue, x, "r") as src, mapped(self.queue, out, "w") as dst:
            dst[...] = scipy.fft.rfft2(src, workers=self.workers)
        return out

    def inverse(self, spectrum, out):
        with mapped(self.queue, spectrum, "r") as src, mapped(self.queue, out, "w") as dst:
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
        """(compiled FFT, complex work array (P, Hp, Wp)) for a (K, Hp, Wp) field."""
        k, hp, wp = field_shape
        return _reikna_plan(self.queue, (-(-k // self.per_transform), hp, wp), self.cdtype)

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


@lru_cache(maxsize=PLAN_CACHE)
def _reikna_plan(queue, shape, cdtype):
    """reikna's compiled complex FFT over axes (1, 2) of ``shape``, and its work array."""
    from reikna.core import Type
    from reikna.fft import FFT

    compiled = FFT(Type(cdtype, shape=shape), axes=(1, 2)).compile(reikna_thread(queue))
    return compiled, cla.empty(queue, shape, cdtype)


@lru_cache(maxsize=PLAN_CACHE)
def reikna_thread(queue):
    """One reikna Thread wrapping our queue."""
    from reikna.cluda import ocl_api

    return ocl_api().Thread(queue)


# ---- VkFFT (optional) -------------------------------------------------------------------------

class VkFFT(RealFFT):
    """pyvkfft's out-of-place R2C / C2R (normalised like numpy).

    VkFFT's C2R reads the self-conjugate columns (k2 = 0, Wp/2) as they are and may overwrite its input, so the
    inverse transforms a Hermitian copy (``fft_hermitian``): irfft2 of any half spectrum, the input kept."""

    name = "vkfft"

    def __init__(self, kernels: Kernels):
        super().__init__(kernels)
        self._scratch = None            # the C2R input: one half spectrum, kept for the last shape
        self._reikna = None             # for planes with a prime factor above 7, made on first use

    def fast_length(self, n: int) -> int:
        return smooth_length(n, VKFFT_PRIMES)

    def engine_for(self, field_shape) -> RealFFT:
        """This engine for a 7-smooth (Hp, Wp) plane, else reikna (see the module docstring)."""
        if all(smooth_length(n, VKFFT_PRIMES) == n for n in field_shape[-2:]):
            return self
        if self._reikna is None:
            self._reikna = ReiknaFFT(self.kernels)
        return self._reikna

    def forward(self, x, out):
        engine = self.engine_for(x.shape)
        if engine is not self:
            return engine.forward(x, out)
        _vkfft_app(self.queue, tuple(x.shape), self.kernels.dtype).fft(x, out)
        return out

    def inverse(self, spectrum, out):
        engine = self.engine_for(out.shape)
        if engine is not self:
            return engine.inverse(spectrum, out)
        k, hp, wp = out.shape
        if self._scratch is None or self._scratch.shape != spectrum.shape:
            self._scratch = cla.empty(self.queue, spectrum.shape, spectrum.dtype)
        wh = np.int32(spectrum.shape[-1])
        self.kernels.grid3("fft_hermitian", spectrum.shape, self._scratch, spectrum, np.int32(hp), np.int32(wp), wh)
        _vkfft_app(self.queue, tuple(out.shape), self.kernels.dtype).ifft(self._scratch, out)
        return out


@lru_cache(maxsize=PLAN_CACHE)
def _vkfft_app(queue, real_shape, dtype):
    """pyvkfft's 2-D R2C/C2R plan over the last two axes of ``real_shape``, out of place, 1/N on the inverse."""
    from pyvkfft.opencl import VkFFTApp

    return VkFFTApp(real_shape, dtype, queue=queue, ndim=2, r2c=True, inplace=False, norm=1)


def vkfft_available() -> bool:
    try:
        import pyvkfft.opencl  # noqa: F401
    except Exception:  # noqa: BLE001 - any import failure means "not available"
        return False
    return True


def available_engines(path: str) -> list[str]:
    """The FFT engines usable on ``path``: host on the host path; reikna, and vkfft when installed, on the device path."""
    if path == "host":
        return ["host"]
    return ["reikna"] + (["vkfft"] if vkfft_available() else [])


def resolve_engine(path: str, engine: str = "auto") -> str:
    """``auto`` -> the path's engine (host; on the device path vkfft if installed, else reikna); others checked."""
    if engine not in ("auto", "host") + DEVICE_ENGINES:
        raise InputError(f"FFT engine {engine!r}: expected one of auto, host, {', '.join(DEVICE_ENGINES)}")
    check_engine(path, engine)
    if engine == "auto":
        return available_engines(path)[-1]
    if engine == "vkfft" and not vkfft_available():
        raise InputError("FFT engine 'vkfft' needs pyvkfft (pip install 'clsdcam[vkfft]', see the README)")
    return engine


def make_fft(queue, path: str, engine: str = "auto", dtype="float32", kernels: Kernels | None = None) -> RealFFT:
    """The FFT engine of ``path`` on ``queue`` for ``dtype`` (``engine`` as in :func:`resolve_engine`)."""
    kernels = kernels or Kernels(queue, dtype)
    name = resolve_engine(path, engine)
    if name == "host":
        return HostFFT(kernels)
    if name == "vkfft":
        return VkFFT(kernels)
    return ReiknaFFT(kernels, pack=True)
