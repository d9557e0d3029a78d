"""The backend contract, in three parts, documented once, and the rule for which code runs it.

A backend owns arrays in one memory (NumPy's, or an OpenCL device's) and keeps two Protocols:

* :class:`Math`, the math primitives the model and the priors are written over (FFTs, geometry, vector
  operations, TV, band mixes, and the factory of A's filtered convolution);
* :class:`Platform`, its memory and plumbing (arrays in and out, host views, the up-front memory check, FFT
  lengths) and what it says of itself (name, dtypes, device, FFT engine, path, threads).

:class:`Programs` is optional too: a backend with compiled kernel programs (OpenCL) lets code outside it launch
the kernels of ``kernels/`` by name (an algorithm's own steps, e.g. ADMM's ``kernels/admm.cl``); code asks
``isinstance(backend, Programs)``, never a backend's name, and passes sizes with :func:`ints` and sums partials
with :func:`total`.

:class:`Fusions` (:data:`FUSIONS`) are optional: one pass over memory for what primitives do in several,
owned by one algorithm (FISTA's momentum step and statistics, the subspace prox). Both backends provide them
under these names and signatures; the algorithm looks one up with ``getattr(backend, name, None)`` and falls
back on the primitives it is made of. :class:`Backend` is Math and Platform together.

Every primitive has the same ``out=`` semantics: it writes into ``out`` when given (no allocation in the
solver's loop) and returns the array holding the result. Layouts: a cube is ``(K, H, W)`` C-contiguous real
(float32, or float64 on request); a spectrum is the real-to-complex half spectrum ``(K, Hp, Wp//2 + 1)`` of a
field ``(K, Hp, Wp)``. Scalars (``vdot``, norms) come back as Python floats, small matrices (``gram``) as
float64 NumPy arrays on the host. A primitive's NumPy form (``numpy.py``, the reference), its kernel in
``kernels/``, and its cases (``cases.py``: the parity tests, ``clsdcam check``, the benchmark) share one name.

Paths: which code runs the heavy primitives.

==========  ================================================  =============================================
path        what runs                                         where
==========  ================================================  =============================================
``host``    host code on host arrays: A and Aᵀ as the         NumPy; OpenCL on CPU devices, on zero-copy
            band-chunked, pruned pocketfft pipeline              mapped buffers (:meth:`Platform.host_view`)
            (``host_convolution``), ``HOST_CODE`` primitives
            by BLAS / cache-blocked NumPy (``host_linalg``,
            ``host_tv``); the rest as the backend's own
            primitives (OpenCL kernels on OpenCL)
``device``  every primitive as an OpenCL kernel, FFTs on the  OpenCL on any device (what GPUs run); A and
            device (VkFFT when installed, else reikna)        Aᵀ as fft2 → cmul → ifft2 → mask_sum
==========  ================================================  =============================================

``auto`` (the default) is ``host`` on CPU devices and NumPy, ``device`` elsewhere (:func:`resolve_path`, the
rule; a backend applies it once, when it is made, and picks its code from the result). The FFT engine follows
the path: ``host`` on the host path; on the device path ``vkfft`` when pyvkfft is importable, else ``reikna``
(``--fft`` picks one of the path's engines).
"""
from __future__ import annotations

from contextlib import AbstractContextManager
from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..errors import InputError

PATHS = ("auto", "host", "device")
HOST_CODE = ("tv_norm", "gram", "bandmix", "subspace_tv")   # host code on the host path, kernels on the device path
HOST_ENGINES = ("host",)
DEVICE_ENGINES = ("reikna", "vkfft")
FUSIONS = ("extrapolate", "fista_stats", "subspace_tv")      # optional: see the module docstring
MAX_MATH = 20                                                # the most methods Math may have


def resolve_path(requested: str, cpu_device: bool) -> str:
    """``host`` or ``device`` for a requested path on a device (``cpu_device``: its memory is the host's)."""
    if requested not in PATHS:
        raise InputError(f"--path {requested!r}: expected one of {', '.join(PATHS)}")
    if requested == "auto":
        return "host" if cpu_device else "device"
    if requested == "host" and not cpu_device:
        raise InputError("--path host runs host code on mapped buffers: CPU devices only (use --path device, or auto)")
    return requested


def check_engine(path: str, engine: str) -> None:
    """InputError when ``engine`` is not one of ``path``'s FFT engines (``auto`` always is)."""
    engines = HOST_ENGINES if path == "host" else DEVICE_ENGINES
    if engine != "auto" and engine not in engines:
        raise InputError(f"--fft {engine!r} is not an engine of the {path} path (its engines: {', '.join(engines)}; "
                         f"{'--path device runs reikna or vkfft' if path == 'host' else '--path host runs host'})")


@runtime_checkable
class Convolution(Protocol):
    """A's filtered convolution on one backend (what :meth:`Math.convolution` returns). With Ĥ the transfer
    function (the sensor window at the FFT origin), F_k the filters and (H, W) the sensor:

        forward:   b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}
        adjoint:   (Aᵀr)_k = irfft2(conj(Ĥ) · rfft2(pad₀(F_k ⊙ r)))
    """

    n_bands: int

    def forward(self, v, out) -> Any:
        """b = A v into ``out`` (H, W)."""

    def adjoint(self, r, out, y=None, step: float = 1.0) -> Any:
        """out = Aᵀr, or the fused gradient step out = y − step·Aᵀr when y is given (out may be y)."""

    def with_filters(self, filters) -> "Convolution":
        """The same transfer and field with other filters (the spectral subspace's G = BᵀF)."""

    def transforms(self) -> int:
        """2-D transforms per forward + adjoint pair."""


@runtime_checkable
class Platform(Protocol):
    """A backend's memory and plumbing, and what it says of itself."""

    name: str            # "numpy" or "opencl"
    dtype: np.dtype      # real dtype of cubes: float32 or float64
    cdtype: np.dtype     # its complex dtype
    device_name: str     # as recorded in output files
    fft_engine: str      # the FFT engine's name
    path: str            # "host" or "device" (see the module docstring)
    workers: int         # host threads for host code

    def to_device(self, host: np.ndarray, complex_: bool = False) -> Any:
        """A contiguous copy of a host array in the backend's (complex) dtype."""

    def to_host(self, array) -> np.ndarray:
        """A NumPy copy of a backend array."""

    def empty(self, shape, complex_: bool = False) -> Any:
        """An uninitialised array: its contents are garbage on a GPU, whatever they are on a CPU."""

    def zeros(self, shape, complex_: bool = False) -> Any:
        """An array of zeros."""

    def copy(self, x, out=None) -> Any:
        """A copy of x (into ``out``)."""

    def host_view(self, array, mode: str) -> AbstractContextManager[np.ndarray]:
        """The array as a NumPy array for the duration of a ``with`` block, without copying (host path only):
        ``mode`` "r" (read), "w" (write: its old contents may be lost) or "rw". Work queued before is done
        when the block starts; what the block writes is seen by work queued after it."""

    def check_problem(self, sensor_shape, field_shape, n_bands: int, field_buffers: int | None = None) -> None:
        """InputError (needed against available memory, and what to do) when one solve cannot fit, its algorithm
        keeping ``field_buffers`` field cubes (None: FISTA's)."""

    def fast_length(self, n: int) -> int:
        """The smallest length ≥ n the FFT engine transforms fast."""


@runtime_checkable
class Math(Protocol):
    """The math primitives (at most :data:`MAX_MATH`): what the model and the priors are written over."""

    # ---- FFT and A ------------------------------------------------------------------------------------
    def fft2(self, x, out=None) -> Any:
        """X = rfft2(x) over the last two axes: (..., Hp, Wp) real → (..., Hp, Wp//2+1) complex."""

    def ifft2(self, spectrum, shape, out=None) -> Any:
        """x = irfft2(X, s=shape) over the last two axes (1/N normalised): the inverse of fft2."""

    def cmul(self, spectrum, transfer, conj: bool = False, out=None) -> Any:
        """X·Ĥ (or X·conj(Ĥ)), Ĥ (Hp, Wp//2+1) broadcast over bands (out may alias X)."""

    def convolution(self, transfer, filters, field_shape, skip_unseen: bool = True) -> Convolution:
        """A's filtered convolution (:class:`Convolution`) for a host transfer function Ĥ (Hp, Wp//2+1) and
        host filters (K, H, W), on this backend's path: the band-chunked, pruned host pipeline on the host path
        (``skip_unseen``: no FFTs for bands no filter sees), fft2 → cmul → ifft2 → mask_sum on the device path."""

    # ---- geometry -------------------------------------------------------------------------------------
    def pad(self, x, field_shape, offset, out=None) -> Any:
        """Zero field of ``field_shape`` (last two axes) with x placed at ``offset`` = (oy, ox). The model crops
        and pads through mask_sum and mask_spread; pad is kept as the primitive other operators use."""

    def crop(self, x, shape, offset, out=None) -> Any:
        """The ``shape`` window of x's last two axes starting at ``offset`` = (oy, ox)."""

    def mask_sum(self, filters, field, offset, out=None) -> Any:
        """b = Σ_k F_k ⊙ crop(field_k): (K,H,W) filters, (K,Hp,Wp) field → (H,W)."""

    def mask_spread(self, filters, r, field_shape, offset, out=None) -> Any:
        """v_k = pad(F_k ⊙ r), the adjoint of mask_sum: (H,W) → (K,Hp,Wp)."""

    # ---- vectors --------------------------------------------------------------------------------------
    def scale(self, a, x, out=None) -> Any:
        """a·x."""

    def axpy(self, a, x, y, out=None) -> Any:
        """a·x + y (out may alias x or y)."""

    def vdot(self, x, y) -> float:
        """⟨x, y⟩, summed with partial sums in float64 (or compensated float32)."""

    def amax(self, x) -> float:
        """max |x|."""

    def nonneg(self, x, out=None) -> Any:
        """max(x, 0)."""

    def soft(self, x, t, out=None) -> Any:
        """Soft threshold sign(x)·max(|x| − t, 0)."""

    def l1_norm(self, x) -> float:
        """Σ |x|."""

    # ---- priors ---------------------------------------------------------------------------------------
    def haar_tv(self, x, tau, weights, out=None, nonneg: bool = False) -> Any:
        """One parallel-proximal Haar step for weighted anisotropic TV (Kamilov 2016), then max(·, 0) if
        ``nonneg``. For the D axes d with weight w_d > 0 (cube axes λ, y, x) and c_d = 2·D·τ·w_d:

            out_i = x_i + 1/(2D) Σ_d [clip((x_{i+1} − x_i)/2, ±c_d) + clip((x_{i−1} − x_i)/2, ±c_d)]

        the average over the 2D shifted one-level Haar transforms of soft-thresholding their detail
        coefficients by 2√2·D·τ·w_d; a missing neighbour (boundary) adds 0. out may alias x."""

    def tv_norm(self, x, weights) -> float:
        """Σ_d w_d Σ_i |x_{i+e_d} − x_i| along each axis d (cube order λ, y, x), in float64."""

    def gram(self, x) -> np.ndarray:
        """G = X Xᵀ (K×K, float64, on the host) of the bands×pixels unfolding X of x."""

    def bandmix(self, x, matrix, out=None) -> Any:
        """out_k = Σ_j M_kj x_j: a K×J host matrix applied along the band axis of x (J bands); out may alias x."""


@runtime_checkable
class Fusions(Protocol):
    """Optional fused forms (:data:`FUSIONS`): each equals the primitives named in its docstring, in one pass."""

    def extrapolate(self, x_new, x_old, beta, out=None) -> Any:
        """FISTA's momentum step x⁺ + β(x⁺ − x) (= axpy(β, x⁺ − x, x⁺)); out may alias x_old, not x_new."""

    def fista_stats(self, x_new, x_old, y) -> tuple[float, float, float]:
        """(‖x⁺ − x‖², ‖x⁺‖², ⟨y − x⁺, x⁺ − x⟩) in one pass (three vdots): FISTA's relative change and restart
        test."""

    def subspace_tv(self, c, basis, tau, weights, out=None) -> Any:
        """c⁺ = Bᵀ·max(0, haar_tv(B·c)) (bandmix, haar_tv with nonneg, bandmix): the TV prox and non-negativity
        in band space for a cube of r coefficients c (r, H, W) in the span of B (K × r, orthonormal columns);
        out may alias c."""


@runtime_checkable
class Programs(Protocol):
    """Optional: the backend's kernel programs for code outside it. ``kernels`` launches a kernel of ``kernels/*.cl``
    by name in one of the launch shapes (``grid1(name, n, *args)``, ``grid2(name, n, rows, *args)``,
    ``grid3(name, (B, H, W), *args)``, ``reduce(name, n, *args, outputs=1)`` → per-group partials on the host, and
    ``row_groups(name, rows, n, *args, local=())``: a work group a row, each looping over its row's n elements
    itself; ``upload(host)`` a device copy of a host array in its own dtype)."""

    kernels: Any

    def drained(self, value) -> Any:
        """``value`` once the queue has finished (a scalar read from the device is then final)."""


def ints(*values) -> list:
    """Sizes and offsets as the kernels' ``int`` arguments."""
    return [np.int32(v) for v in values]


def total(partials: np.ndarray) -> float:
    """A reduction's per-group partials added on the host, in float64."""
    return float(np.sum(partials, dtype=np.float64))


@runtime_checkable
class Backend(Math, Platform, Protocol):
    """A whole backend: the math primitives and the platform (NumPy: ``numpy.NumpyBackend``; OpenCL:
    ``opencl.OpenCLBackend``), with the optional fusions beside."""


def protocol_members(protocol: type = Backend) -> tuple[str, ...]:
    """The names of a contract's methods (its own and those of the contracts it joins; for tests and tools)."""
    names: dict[str, None] = {}
    for cls in reversed(protocol.__mro__):
        if cls.__module__ == __name__:
            names.update((name, None) for name, value in vars(cls).items()
                         if callable(value) and not name.startswith("_"))
    return tuple(names)


def protocol_attributes(protocol: type = Platform) -> tuple[str, ...]:
    """The names of a contract's attributes."""
    return tuple(name for cls in reversed(protocol.__mro__) if cls.__module__ == __name__
                 for name in vars(cls).get("__annotations__", {}))
