"""Every primitive's cases in one table, read by the parity tests (``tests/test_parity.py``), ``clsdcam check``
(``clsdcam/devcheck.py``) and the kernel benchmark (``tools/bench_kernels.py``).

A :class:`Case` is one call of a primitive of the contract (``base.py``: Math, Platform, Fusions) on seeded inputs
of one size (:class:`Inputs`): the arrays it moves to the backend, the call (the same on every backend; the NumPy
backend's result is the reference), the rule its error must meet, and, on each primitive's benchmark case, the
bytes it must read and write at the least (for its GB/s). The error is relative to the reference's largest value,

    error = max |got − ref| / max |ref|

and the rules are

    ``elementwise``  1e-6   (every cube-valued primitive, the band mixes' sums of K products included)
    ``reduction``    1e-5   (sums over a cube: vdot, amax, l1_norm, tv_norm, gram, fista_stats)
    ``fft``          2e-6 + 5e-7·log10 N, N = Hp·Wp   (pyvkfft's own test tolerance)

Adding a primitive: its cases here (a benchmark case with ``moved``, named as the primitive, and variants for
aliasing and special arguments); every consumer picks them up.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np

ELEMENTWISE, REDUCTION = 1e-6, 1e-5
RANK = 3              # coefficients of the subspace cases (at most K − 1)


def fft_tolerance(n: int) -> float:
    """2e-6 + 5e-7·log10 n for transforms of n points (pyvkfft's)."""
    return 2e-6 + 5e-7 * math.log10(n)


RULES = {"elementwise": lambda a: ELEMENTWISE, "reduction": lambda a: REDUCTION,
         "fft": lambda a: fft_tolerance(a.field_shape[0] * a.field_shape[1])}


def relative_error(got, ref) -> float:
    """max |got − ref| / max |ref| (inf when the shapes differ)."""
    got, ref = np.asarray(got, np.complex128), np.asarray(ref, np.complex128)
    if got.shape != ref.shape:
        return math.inf
    return float(np.max(np.abs(got - ref)) / (np.max(np.abs(ref)) or 1.0))


# name -> (shape at an Inputs a, how it is drawn); each array from its own stream (seed, index)
ARRAYS = {
    "field": (lambda a: (a.bands,) + a.field_shape, "normal"),
    "field2": (lambda a: (a.bands,) + a.field_shape, "normal"),
    "wide": (lambda a: (a.bands + 2,) + a.field_shape, "normal"),
    "coefficients": (lambda a: (a.rank,) + a.field_shape, "normal"),
    "window": (lambda a: (a.bands,) + a.sensor, "normal"),
    "filters": (lambda a: (a.bands,) + a.sensor, "uniform"),
    "image": (lambda a: a.sensor, "normal"),
    "spectrum": (lambda a: (a.bands,) + a.half, "complex"),
    "transfer": (lambda a: a.half, "complex"),
    "mix": (lambda a: (a.bands, a.bands), "matrix"),
    "basis": (lambda a: (a.bands, a.rank), "orthonormal"),
}
DRAWS = {
    "normal": lambda rng, shape, dtype: rng.standard_normal(shape).astype(dtype),
    "uniform": lambda rng, shape, dtype: rng.random(shape).astype(dtype),
    "complex": lambda rng, shape, dtype: (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(
        np.result_type(dtype, np.complex64)),
    "matrix": lambda rng, shape, dtype: rng.standard_normal(shape),                  # host float64
    "orthonormal": lambda rng, shape, dtype: np.linalg.qr(rng.standard_normal(shape))[0],
}


class Inputs:
    """Seeded host arrays of one size, ``a[name]`` (:data:`ARRAYS`), each drawn on first use: K ``bands``, the
    ``sensor`` (H, W) window at the centre (``offset``) of the ``field`` (Hp, Wp), r = min(RANK, K − 1)
    coefficients of a K × r orthonormal basis."""

    def __init__(self, bands: int, sensor, field, dtype="float32", seed: int = 0):
        self.bands, self.sensor, self.field_shape = int(bands), tuple(sensor), tuple(field)
        self.offset = tuple((f - s) // 2 for f, s in zip(self.field_shape, self.sensor))
        self.half = (self.field_shape[0], self.field_shape[1] // 2 + 1)
        self.rank = max(1, min(RANK, self.bands - 1))
        self.dtype, self.seed = np.dtype(dtype), seed
        self._arrays: dict[str, np.ndarray] = {}

    def __getitem__(self, name: str) -> np.ndarray:
        if name not in self._arrays:
            shape, draw = ARRAYS[name]
            rng = np.random.default_rng((self.seed, list(ARRAYS).index(name)))
            self._arrays[name] = DRAWS[draw](rng, shape(self), self.dtype)
        return self._arrays[name]

    def nbytes(self, name: str) -> int:
        """Bytes of array ``name`` on a backend (without drawing it)."""
        shape, draw = ARRAYS[name]
        return math.prod(shape(self)) * self.dtype.itemsize * (2 if draw == "complex" else 1)


@dataclass(frozen=True)
class Case:
    """One call of a primitive (see the module docstring): ``call(be, a, *arrays, out=None)`` on the backend's copies
    of the ``uses`` arrays of Inputs ``a``; ``moved(a)``: the least bytes read and written (benchmark cases)."""

    name: str
    uses: tuple
    call: Callable
    rule: str = "elementwise"
    moved: Callable | None = None

    def tolerance(self, a: Inputs) -> float:
        return RULES[self.rule](a)

    def arrays(self, be, a: Inputs) -> list:
        """The ``uses`` arrays, moved to ``be`` (fresh copies)."""
        return [be.to_device(a[name], complex_=np.iscomplexobj(a[name])) for name in self.uses]

    def run(self, be, a: Inputs):
        """The call on fresh copies; its result on the host (a NumPy array or a float)."""
        result = self.call(be, a, *self.arrays(be, a))
        return result if isinstance(result, (float, np.ndarray)) else be.to_host(result)

    def error(self, be, reference, a: Inputs) -> float:
        """The relative error of ``be``'s result against ``reference``'s (the NumPy backend)."""
        return relative_error(self.run(be, a), self.run(reference, a))

    def timed(self, be, a: Inputs) -> Callable[[], object]:
        """The call as a function of nothing, for timing: arrays moved once, the output of a first call reused."""
        arrays = self.arrays(be, a)
        out = self.call(be, a, *arrays)
        return lambda: self.call(be, a, *arrays, out=out)


def _cube(count: int, name: str = "field") -> Callable[[Inputs], int]:
    """``count`` times the bytes of one ``name`` array (a cube read or written)."""
    return lambda a: count * a.nbytes(name)


def _sum(*names: str) -> Callable[[Inputs], int]:
    """The bytes of the ``names`` arrays together (a name twice counts twice)."""
    return lambda a: sum(a.nbytes(name) for name in names)


def _stats(be, x, x_old, wide):
    """fista_stats with y a view of the first K bands of a larger cube (an offset-0 sub-buffer)."""
    return np.array(be.fista_stats(x, x_old, wide[:x.shape[0]]))


_CASES = [
    # ---- memory and FFT --------------------------------------------------------------------------
    Case("copy", ("field",), lambda be, a, x, out=None: be.copy(x, out=out), moved=_cube(2)),
    Case("fft2", ("field",), lambda be, a, x, out=None: be.fft2(x, out=out), "fft", _sum("field", "spectrum")),
    Case("ifft2", ("spectrum",), lambda be, a, s, out=None: be.ifft2(s, a.field_shape, out=out), "fft",
         _sum("spectrum", "field")),
    Case("fft2_roundtrip", ("field",), lambda be, a, x, out=None: be.ifft2(be.fft2(x), a.field_shape, out=out), "fft"),
    Case("cmul", ("spectrum", "transfer"), lambda be, a, s, t, out=None: be.cmul(s, t, out=out),
         moved=_cube(2, "spectrum")),
    Case("cmul_conj", ("spectrum", "transfer"), lambda be, a, s, t, out=None: be.cmul(s, t, conj=True, out=out)),
    Case("cmul_inplace", ("spectrum", "transfer"), lambda be, a, s, t, out=None: be.cmul(s, t, out=s)),
    # ---- geometry --------------------------------------------------------------------------------
    Case("pad", ("window",), lambda be, a, w, out=None: be.pad(w, a.field_shape, a.offset, out=out),
         moved=_sum("window", "field")),
    Case("pad_2d", ("image",), lambda be, a, i, out=None: be.pad(i, a.field_shape, a.offset, out=out)),
    Case("crop", ("field",), lambda be, a, x, out=None: be.crop(x, a.sensor, a.offset, out=out),
         moved=_cube(2, "window")),
    Case("mask_sum", ("filters", "field"), lambda be, a, f, x, out=None: be.mask_sum(f, x, a.offset, out=out),
         moved=_sum("filters", "window", "image")),
    Case("mask_spread", ("filters", "image"),
         lambda be, a, f, r, out=None: be.mask_spread(f, r, a.field_shape, a.offset, out=out),
         moved=_sum("filters", "image", "field")),
    # ---- vectors ---------------------------------------------------------------------------------
    Case("scale", ("field",), lambda be, a, x, out=None: be.scale(-0.37, x, out=out), moved=_cube(2)),
    Case("axpy", ("field", "field2"), lambda be, a, x, y, out=None: be.axpy(-0.37, x, y, out=out), moved=_cube(3)),
    Case("axpy_alias_x", ("field", "field2"), lambda be, a, x, y, out=None: be.axpy(0.8, x, y, out=x)),
    Case("axpy_alias_y", ("field", "field2"), lambda be, a, x, y, out=None: be.axpy(0.8, x, y, out=y)),
    Case("extrapolate", ("field", "field2"), lambda be, a, x, y, out=None: be.extrapolate(x, y, 0.61, out=out),
         moved=_cube(3)),
    Case("extrapolate_alias", ("field", "field2"), lambda be, a, x, y, out=None: be.extrapolate(x, y, 0.61, out=y)),
    Case("nonneg", ("field",), lambda be, a, x, out=None: be.nonneg(x, out=out), moved=_cube(2)),
    Case("soft", ("field",), lambda be, a, x, out=None: be.soft(x, 0.4, out=out), moved=_cube(2)),
    Case("vdot", ("field", "field2"), lambda be, a, x, y, out=None: be.vdot(x, y), "reduction", _cube(2)),
    Case("amax", ("field",), lambda be, a, x, out=None: be.amax(x), "reduction", _cube(1)),
    Case("l1_norm", ("field",), lambda be, a, x, out=None: be.l1_norm(x), "reduction", _cube(1)),
    Case("fista_stats", ("field", "field2", "wide"), lambda be, a, *xs, out=None: _stats(be, *xs), "reduction",
         _cube(3)),
    # ---- priors ----------------------------------------------------------------------------------
    Case("haar_tv", ("field",), lambda be, a, x, out=None: be.haar_tv(x, 0.05, (1.0, 1.0, 1.0), out=out),
         moved=_cube(2)),
    Case("haar_tv_weighted", ("field",), lambda be, a, x, out=None: be.haar_tv(x, 0.3, (0.0, 0.5, 2.0), out=out)),
    Case("haar_tv_bands_only", ("field",), lambda be, a, x, out=None: be.haar_tv(x, 0.1, (1.0, 0.0, 0.0), out=out)),
    Case("haar_tv_none", ("field",), lambda be, a, x, out=None: be.haar_tv(x, 0.1, (0.0, 0.0, 0.0), out=out)),
    Case("haar_tv_alias", ("field",), lambda be, a, x, out=None: be.haar_tv(x, 0.05, (1.0, 2.0, 0.5), out=x)),
    Case("haar_tv_nonneg", ("field",),
         lambda be, a, x, out=None: be.haar_tv(x, 0.05, (1.0, 2.0, 0.5), out=out, nonneg=True)),
    Case("tv_norm", ("field",), lambda be, a, x, out=None: be.tv_norm(x, (1.0, 0.5, 2.0)), "reduction", _cube(1)),
    Case("tv_norm_xy", ("field",), lambda be, a, x, out=None: be.tv_norm(x, (0.0, 1.0, 1.0)), "reduction"),
    Case("gram", ("field",), lambda be, a, x, out=None: be.gram(x), "reduction", _cube(1)),
    Case("bandmix", ("field",), lambda be, a, x, out=None: be.bandmix(x, a["mix"], out=out), moved=_cube(2)),
    Case("bandmix_alias", ("field",), lambda be, a, x, out=None: be.bandmix(x, a["mix"], out=x)),
    Case("bandmix_expand", ("coefficients",), lambda be, a, c, out=None: be.bandmix(c, a["basis"], out=out)),
    Case("bandmix_project", ("field",), lambda be, a, x, out=None: be.bandmix(x, a["basis"].T, out=out)),
    Case("bandmix_projector", ("field",), lambda be, a, x, out=None: be.bandmix(x, a["basis"] @ a["basis"].T, out=out)),
    Case("subspace_tv", ("coefficients",),
         lambda be, a, c, out=None: be.subspace_tv(c, a["basis"], 0.05, (1.0, 1.0, 1.0), out=out),
         moved=_cube(2, "coefficients")),
    Case("subspace_tv_weighted", ("coefficients",),
         lambda be, a, c, out=None: be.subspace_tv(c, a["basis"], 0.2, (0.0, 0.5, 2.0), out=out)),
]
CASES = {case.name: case for case in _CASES}


def case_names(rule: str | None = None) -> list[str]:
    """The names of the cases (of one rule)."""
    return [name for name, case in CASES.items() if rule in (None, case.rule)]


def benchmarks() -> list[Case]:
    """Each primitive's benchmark case (those with ``moved``), in table order."""
    return [case for case in CASES.values() if case.moved is not None]
