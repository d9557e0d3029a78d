"""ADMM's closed-form steps for the filter-array camera, in band space (:mod:`clsdcam.algorithms.admm` runs them).

The problem, on the field (K, Hp, Wp) in the solver's units:

    min_{v ≥ 0} ½‖b − S·F·H v‖² + τ Σ_d w_d ‖D_d v‖₁ (+ τ₁‖v‖₁)

with H the PSF's circular convolution (its output frame has the sensor window at the origin), F the filters
(per sensor pixel p, the K values f_p: (F x)_p = f_pᵀ x_p), S the window, and D_d the forward differences along
the cube's axes d = λ, y, x (circular on the field's y and x; along λ the last difference is 0). Three splits,
each with its scaled dual: x = H·v (data), u_d = D_d·v (TV), w = v (non-negativity, and L1). One iteration:

* **c-step**, the only transforms: v = argmin μ₁/2‖Hv − x + ξ‖² + μ₂/2 Σ_d‖D_d v − u_d + η_d‖² + μ₃/2‖v − w + ρ‖²,

      (μ₁HᵀH + μ₂ΣD_dᵀD_d + μ₃I) v = μ₁Hᵀ(x − ξ) + μ₂ΣD_dᵀ(u_d − η_d) + μ₃(w − ρ)

  HᵀH and the spatial D_yᵀD_y, D_xᵀD_x are diagonal in the 2-D Fourier basis (|Ĥ|², 2 − 2cos(2πk/N)); D_λᵀD_λ,
  the path graph's Laplacian along the bands, is diagonal in the orthonormal DCT-II along λ (eigenvalues
  Λ_j = 2 − 2cos(πj/K)). So the system is one division per Fourier coefficient and DCT index:

      v̂ = IDCT_λ[ DCT_λ(μ₁conj(Ĥ)·rfft2(x − ξ) + rfft2(μ₂ΣD_dᵀ(u_d − η_d) + μ₃(w − ρ)))
                  / (μ₁|Ĥ|² + μ₂(|d̂_y|² + |d̂_x|²) + μ₂Λ_j + μ₃) ]

  then v = irfft2(v̂) and Hv = irfft2(Ĥ·v̂): 2K forward and 2K inverse transforms, as one FISTA gradient.
* **x-step**, per pixel (Sherman–Morrison): with q = Hv + ξ, argmin ½(b_p − f_pᵀx_p)² + μ₁/2‖x_p − q_p‖² is
  x_p = q_p + f_p·(b_p − f_pᵀq_p)/(μ₁ + ‖f_p‖²) on the sensor window, x_p = q_p outside it.
* **u-step**: u_d = soft(D_d v + η_d, τw_d/μ₂), the exact prox of the anisotropic TV (not the Haar average FISTA
  uses: the two minimisers differ, so compare them against the truth, not the objective).
* **w-step**: w = max(v + ρ − τ₁/μ₃, 0) (no L1 term: τ₁ = 0).

Each split's dual follows its step: with q = K·v + dual, z = prox(q), dual⁺ = q − z, so what the next c-step needs
of the split, z − dual⁺ = 2z − q, is formed in the same pass, and neither u nor x is kept:

* data: ξ⁺ = −f_p·(b_p − f_pᵀq_p)/(μ₁ + ‖f_p‖²) on the window and 0 outside it (kept on the window only), and
  x − ξ⁺ = q + 2(x − q) is written over Hv;
* TV: η_d⁺ = clip(q, ±τw_d/μ₂) (the soft threshold's remainder) and s_d = u_d − η_d⁺ = q − 2η_d⁺;
* non-negativity: ρ⁺ = q − w and μ₃(w − ρ⁺), the start of the next right-hand side, to which one more pass adds
  μ₂ΣD_dᵀs_d.

On NumPy (:class:`Splitting`) both passes and the spectral division run on cache-sized row blocks on the host's
threads (``backends/blocks``): the iteration reads each cube about twice besides its transforms. On OpenCL they are
kernels (:mod:`clsdcam.kernel_splitting`). The duals are scaled (ξ = λ/μ₁); the penalties are
relative to the problem's own scales (:class:`Penalties`, :mod:`clsdcam.algorithms.admm`).
"""
from __future__ import annotations

from dataclasses import astuple, dataclass

import numpy as np
import scipy.fft

from .backends.blocks import map_blocks, scratch_buffer
from .geometry import transfer_function

FFT_CHUNK_BYTES = 4 << 20     # spectrum bytes per chunk of bands in the transforms (host_convolution's)


@dataclass
class Penalties:
    """μ₁ (data split), μ₂ (TV split), μ₃ (non-negativity split), absolute."""

    data: float
    tv: float
    nonneg: float


@dataclass
class SplitState:
    """ADMM's arrays: v and Hv (the c-step's; Hv then holds x − ξ), ξ on the sensor window, ρ, w (the iterate),
    η_d and s_d = u_d − η_d per active TV axis, the right-hand side's rest, the two spectra."""

    v: np.ndarray
    hv: np.ndarray
    xi: np.ndarray
    rho: np.ndarray
    w: np.ndarray
    eta: np.ndarray
    s: np.ndarray
    rest: np.ndarray
    spectra: tuple


def band_eigenvalues(n_bands: int) -> np.ndarray:
    """Λ_j = 2 − 2cos(πj/K): the eigenvalues of DᵀD for the first differences along λ (last one 0), whose
    eigenvectors are the orthonormal DCT-II's."""
    return 2.0 - 2.0 * np.cos(np.pi * np.arange(n_bands) / n_bands)


def difference_spectrum(n: int, half: bool = False) -> np.ndarray:
    """|d̂(k)|² = 2 − 2cos(2πk/n) of the circular forward difference (k < n//2 + 1 when ``half``)."""
    k = np.arange(n // 2 + 1 if half else n)
    return 2.0 - 2.0 * np.cos(2.0 * np.pi * k / n)


def _along(axis: int, index) -> tuple:
    return tuple(index if a == axis else slice(None) for a in range(3))


def _rows_run(a: np.ndarray) -> np.ndarray:
    """(K, n, W) viewed as (K, n·W): each plane's rows as one run (a view for a block of a cube's rows)."""
    return a.reshape(a.shape[0], -1)


def difference(v: np.ndarray, axis: int, out: np.ndarray, below=None) -> np.ndarray:
    """D_d v: v[i + 1] − v[i] along ``axis`` (0: λ, the last difference 0; 2: circular; 1: circular, or with the
    row ``below`` the last one given (a block of a cube's rows)). Along x into a contiguous ``out`` the differences
    are taken along each plane's rows as one run (long inner loops), the last column's then put right."""
    n = v.shape[axis]
    if axis == 2 and out.flags.c_contiguous:
        run = _rows_run(v)
        np.subtract(run[:, 1:], run[:, :-1], out=_rows_run(out)[:, :-1])
    else:
        np.subtract(v[_along(axis, slice(1, n))], v[_along(axis, slice(0, n - 1))],
                    out=out[_along(axis, slice(0, n - 1))])
    last = _along(axis, n - 1)
    if axis == 0:
        out[last] = 0
    else:
        after = v[_along(axis, 0)] if below is None else below
        np.subtract(after, v[last], out=out[last])
    return out


def difference_adjoint_add(u: np.ndarray, axis: int, scale: float, out: np.ndarray, above=None,
                           scratch: dict | None = None) -> np.ndarray:
    """out += scale·D_dᵀu: (D_dᵀu)[i] = u[i − 1] − u[i] (along λ u[−1] = 0 and u[K−1] unused; along y the row
    ``above`` the first one may be given, a block of a cube's rows; else circular). Along x, scale·u[i − 1] is
    formed whole (each plane's rows as one run, the first column's then put right) and added in one pass."""
    n = u.shape[axis]
    if axis == 0:
        out[_along(0, slice(0, n - 1))] -= scale * u[_along(0, slice(0, n - 1))]
        out[_along(0, slice(1, n))] += scale * u[_along(0, slice(0, n - 1))]
        return out
    out -= scale * u
    if axis == 2:
        dtype = np.result_type(u, scale)           # as scale·u would be (a float64 scale: formed in float64)
        shifted = np.empty(u.shape, dtype) if scratch is None else scratch_buffer(scratch, "shifted", u.shape, dtype)
        np.multiply(_rows_run(u)[:, :-1], scale, out=_rows_run(shifted)[:, 1:])
        np.multiply(u[..., n - 1], scale, out=shifted[..., 0])
        out += shifted
        return out
    out[_along(axis, slice(1, n))] += scale * u[_along(axis, slice(0, n - 1))]
    before = u[_along(axis, n - 1)] if above is None else above
    out[_along(axis, 0)] += scale * before
    return out


class CalibrationTerms:
    """What the steps need of one model's calibration alone, the filters f_p with their energies ‖f_p‖² and the
    transfer function Ĥ with |Ĥ|², and of the penalties, the x-step's gains f_p/(μ₁ + ‖f_p‖²), μ₁conj(Ĥ) and the
    c-step's divisors: built once and kept by the solver, so a video's frames do not rebuild them (the divisors
    alone are a float64 pass over the whole spectrum); the terms of the last penalties are kept."""

    def __init__(self, model, filters: np.ndarray):
        self.dtype = np.dtype(model.backend.dtype)
        self.cdtype = np.result_type(self.dtype, np.complex64)
        self.field_shape, self.n_bands = model.field_shape, model.n_bands
        self.filters = np.ascontiguousarray(filters, self.dtype)
        self.filter_energy = np.einsum("khw,khw->hw", self.filters, self.filters, dtype=np.float64)
        self.transfer = transfer_function(model.psf, model.geometry).astype(self.cdtype)
        self.transfer_power = np.abs(self.transfer.astype(np.complex128)) ** 2
        self._last = None           # ((penalties, TV axes), (gains, μ₁conj(Ĥ), divisors))
        self._uploads: dict = {}    # term name -> (backend, host array, its device copy)

    def for_penalties(self, p: Penalties, axes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(f_p/(μ₁ + ‖f_p‖²), μ₁conj(Ĥ), 1/(μ₁|Ĥ|² + μ₂(|d̂_y|² + |d̂_x|² + Λ_j) + μ₃)), TV's terms on ``axes`` only."""
        key = (astuple(p), tuple(axes))
        if self._last is None or self._last[0] != key:
            self._last = (key, self._penalty_terms(p, axes))
        return self._last[1]

    def on_device(self, backend, name: str, host: np.ndarray, complex_: bool = False):
        """``host``, the term called ``name``, on ``backend``'s device: uploaded once, and again only when the backend
        or the host array (new penalties, new terms) is another."""
        kept = self._uploads.get(name)
        if kept is None or kept[0] is not backend or kept[1] is not host:
            kept = (backend, host, backend.to_device(host, complex_))
            self._uploads[name] = kept
        return kept[2]

    def _penalty_terms(self, p: Penalties, axes) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        gain = (self.filters / (p.data + self.filter_energy)).astype(self.dtype)
        data_transfer = (p.data * np.conj(self.transfer)).astype(self.cdtype)
        hp, wp = self.field_shape
        spatial = p.data * self.transfer_power
        if 1 in axes:
            spatial = spatial + p.tv * difference_spectrum(hp)[:, None]
        if 2 in axes:
            spatial = spatial + p.tv * difference_spectrum(wp, half=True)[None, :]
        spectral = p.tv * band_eigenvalues(self.n_bands) if 0 in axes else np.zeros(self.n_bands)
        return gain, data_transfer, (1.0 / (spatial[None] + spectral[:, None, None] + p.nonneg)).astype(self.dtype)


class SplittingBase:
    """What ADMM's steps share on every backend: the problem's shapes and scales, and the penalties with what depends
    on them. ``model``: the band space's :class:`~clsdcam.model.ForwardModel`; ``terms`` its
    :class:`CalibrationTerms`; ``tv`` the :class:`~clsdcam.priors.TotalVariation` prior or None, ``l1`` the
    :class:`~clsdcam.priors.Sparsity` prior or None (their weights are read at every step: an automatic weight chosen
    mid-solve takes effect at once). A backend's steps (:class:`Splitting` on NumPy,
    :class:`clsdcam.kernel_splitting.KernelSplitting` on OpenCL) add ``start``, ``c_step`` and ``splits``."""

    def __init__(self, model, terms: CalibrationTerms, tv=None, l1=None):
        self.terms = terms
        self.dtype, self.cdtype = terms.dtype, terms.cdtype
        self.field_shape = model.field_shape
        self.sensor_shape = model.sensor_shape
        self.shape = model.cube_shape
        self.n_bands = model.n_bands
        self.tv, self.l1 = tv, l1
        self.axes = [axis for axis, weight in enumerate(tv.axis_weights) if weight > 0] if tv is not None else []
        self.penalties: Penalties | None = None

    # ---- the problem's scales ------------------------------------------------------------------------------
    @property
    def data_curvature(self) -> float:
        """The mean of ‖f_p‖² over the sensor: the x-step's curvature from the data term."""
        return float(np.mean(self.terms.filter_energy))

    @property
    def transfer_peak(self) -> float:
        """max |Ĥ|² (the DC gain squared for a non-negative PSF)."""
        return float(self.terms.transfer_power.max())

    def set_penalties(self, penalties: Penalties):
        """The penalties, and what depends on them (:meth:`CalibrationTerms.for_penalties`)."""
        self.penalties = penalties
        self._gain, self._data_transfer, self._inverse = self.terms.for_penalties(penalties, self.axes)

    def threshold(self, axis: int) -> float:
        """The u-step's soft threshold τw_d/μ₂ along ``axis``."""
        return self.tv.weight * self.tv.axis_weights[axis] / self.penalties.tv

    def nonneg_shift(self) -> float:
        """The w-step's shift τ₁/μ₃ (0 without the L1 prior)."""
        return self.l1.weight / self.penalties.nonneg if self.l1 is not None else 0.0

    def iterate(self, state) -> tuple[float, tuple[float, float]]:
        """The c-step then the splits: (½‖b − SFHv‖² at the new v, (‖w⁺ − w‖², ‖w⁺‖²))."""
        self.c_step(state)
        return self.splits(state)


class Splitting(SplittingBase):
    """ADMM's steps for one band-space problem (see the module docstring) on NumPy arrays, in row blocks on
    ``workers`` threads; ``b`` the normalised measurement."""

    def __init__(self, model, b: np.ndarray, terms: CalibrationTerms, tv=None, l1=None, workers: int = 1):
        super().__init__(model, terms, tv, l1)
        self.workers = workers
        self.b = np.asarray(b, self.dtype)
        self.filters, self.transfer = terms.filters, terms.transfer
        self.chunk = max(1, FFT_CHUNK_BYTES // (self.field_shape[0] * (self.field_shape[1] // 2 + 1) *
                                                np.dtype(self.cdtype).itemsize))

    # ---- the state -----------------------------------------------------------------------------------------
    def start(self, v0: np.ndarray) -> tuple[SplitState, float]:
        """The state from v = v0 with zero duals: Hv by one convolution (2K transforms), then every split's step;
        and the data term at v0."""
        cube, spectrum = self.shape, (self.n_bands, self.field_shape[0], self.field_shape[1] // 2 + 1)
        per_axis = (len(self.axes),) + cube
        zeros = np.zeros
        state = SplitState(v=np.array(v0, self.dtype), hv=zeros(cube, self.dtype),
                           xi=zeros((self.n_bands,) + self.sensor_shape, self.dtype), rho=zeros(cube, self.dtype),
                           w=zeros(cube, self.dtype), eta=zeros(per_axis, self.dtype), s=zeros(per_axis, self.dtype),
                           rest=zeros(cube, self.dtype),
                           spectra=(zeros(spectrum, self.cdtype), zeros(spectrum, self.cdtype)))
        state.hv[...] = self.convolve(state.v)
        data, _ = self.splits(state)
        return state, data

    # ---- one iteration -------------------------------------------------------------------------------------
    def c_step(self, state: SplitState) -> None:
        """v and Hv from the right-hand side the last splits left (x − ξ in ``hv``, the rest in ``rest``)."""
        self._add_tv_adjoint(state)
        data, rest = state.spectra
        self._rfft2(state.hv, data)
        self._rfft2(state.rest, rest)
        self._divide(data, rest)                 # v̂ into ``data``, Ĥ·v̂ into ``rest``
        self._irfft2(data, state.v)
        self._irfft2(rest, state.hv)

    def splits(self, state: SplitState) -> tuple[float, tuple[float, float]]:
        """Every split's step and dual on row blocks, and what the next c-step needs of them (the module
        docstring); the data term at v and the change of w."""
        k, hp, wp = self.shape
        parts = map_blocks(lambda y0, y1, scratch: self._split_block(state, y0, y1, scratch), hp,
                           k * wp * self.dtype.itemsize, self.workers)
        data, step, norm = (float(np.sum([p[i] for p in parts], dtype=np.float64)) for i in range(3))
        return data, (step, norm)

    # ---- the passes ----------------------------------------------------------------------------------------
    def _split_block(self, state: SplitState, y0: int, y1: int, scratch: dict) -> tuple[float, float, float]:
        data = self._x_block(state, y0, y1)
        step, norm = self._w_block(state, y0, y1, scratch)
        self._u_block(state, y0, y1, scratch)
        return data, step, norm

    def _x_block(self, state: SplitState, y0: int, y1: int) -> float:
        """q = Hv + ξ on the window's rows of the block; ξ ← −f·(b − fᵀq)/(μ₁ + ‖f‖²); Hv ← q − 2ξ (= x − ξ⁺)."""
        h, w = self.sensor_shape
        if y0 >= h:
            return 0.0
        rows = slice(y0, min(y1, h))
        q = state.hv[:, rows, :w]
        f, b = self.filters[:, rows], self.b[rows]
        fitted = np.einsum("khw,khw->hw", f, q)
        residual = fitted - b
        q += state.xi[:, rows]
        misfit = b - np.einsum("khw,khw->hw", f, q)
        np.multiply(self._gain[:, rows], -misfit, out=state.xi[:, rows])
        q -= 2.0 * state.xi[:, rows]
        return 0.5 * float(np.vdot(residual.astype(np.float64), residual))

    def _w_block(self, state: SplitState, y0: int, y1: int, scratch: dict) -> tuple[float, float]:
        """q = v + ρ; w ← max(q − τ₁/μ₃, 0); ρ ← q − w; rest ← μ₃(w − ρ); (‖w⁺ − w‖², ‖w⁺‖²) over the block."""
        p = self.penalties
        q = np.add(state.v[:, y0:y1], state.rho[:, y0:y1], out=state.rho[:, y0:y1])
        new = scratch_buffer(scratch, "w", q.shape, q.dtype)
        shift = self.nonneg_shift()
        np.subtract(q, shift, out=new) if shift else np.copyto(new, q)
        np.maximum(new, 0, out=new)
        old = state.w[:, y0:y1]
        old -= new
        step = float(np.vdot(old.ravel(), old.ravel()))
        old[...] = new
        q -= new                                              # ρ⁺
        rest = np.subtract(new, q, out=state.rest[:, y0:y1])
        rest *= p.nonneg
        return step, float(np.vdot(new.ravel(), new.ravel()))

    def _u_block(self, state: SplitState, y0: int, y1: int, scratch: dict) -> None:
        """q = D_d v + η_d; η_d ← clip(q, ±τw_d/μ₂); s_d ← q − 2η_d, per active axis."""
        v = state.v
        q = scratch_buffer(scratch, "q", (self.n_bands, y1 - y0, self.shape[2]), self.dtype)
        for i, axis in enumerate(self.axes):
            block = v[:, y0:y1]
            if axis == 1:
                difference(block, 1, q, below=v[:, y1 % self.shape[1]])
            else:
                difference(block, axis, q)
            eta = state.eta[i, :, y0:y1]
            q += eta
            threshold = self.threshold(axis)
            np.clip(q, -threshold, threshold, out=eta)
            np.subtract(q, eta, out=state.s[i, :, y0:y1])
            state.s[i, :, y0:y1] -= eta

    def _add_tv_adjoint(self, state: SplitState) -> None:
        """rest += μ₂ΣD_dᵀs_d on row blocks."""
        k, hp, wp = self.shape
        mu = self.penalties.tv

        def block(y0, y1, scratch):
            out = state.rest[:, y0:y1]
            for i, axis in enumerate(self.axes):
                s = state.s[i]
                above = s[:, (y0 - 1) % hp] if axis == 1 else None
                difference_adjoint_add(s[:, y0:y1], axis, mu, out, above=above, scratch=scratch)

        if self.axes:
            map_blocks(block, hp, k * wp * self.dtype.itemsize, self.workers)

    def _divide(self, data: np.ndarray, rest: np.ndarray) -> None:
        """data ← v̂ = IDCT_λ[DCT_λ(μ₁conj(Ĥ)·data + rest)/divisor], rest ← Ĥ·v̂, on row blocks of the spectra."""
        k, rows, cols = data.shape

        def block(y0, y1, _scratch):
            spectrum = data[:, y0:y1]
            spectrum *= self._data_transfer[y0:y1]
            spectrum += rest[:, y0:y1]
            rotated = scipy.fft.dct(spectrum, type=2, norm="ortho", axis=0)
            rotated *= self._inverse[:, y0:y1]
            spectrum[...] = scipy.fft.idct(rotated, type=2, norm="ortho", axis=0, overwrite_x=True)
            np.multiply(spectrum, self.transfer[y0:y1], out=rest[:, y0:y1])

        map_blocks(block, rows, k * cols * data.itemsize, self.workers)

    def _rfft2(self, x: np.ndarray, out: np.ndarray) -> None:
        for k0 in range(0, self.n_bands, self.chunk):
            out[k0:k0 + self.chunk] = scipy.fft.rfft2(x[k0:k0 + self.chunk], workers=self.workers)

    def _irfft2(self, spectrum: np.ndarray, out: np.ndarray) -> None:
        for k0 in range(0, self.n_bands, self.chunk):
            out[k0:k0 + self.chunk] = scipy.fft.irfft2(spectrum[k0:k0 + self.chunk], s=self.field_shape,
                                                       workers=self.workers)

    def convolve(self, v: np.ndarray) -> np.ndarray:
        """Hv = irfft2(Ĥ·rfft2(v)) (the start's; 2K transforms)."""
        return scipy.fft.irfft2(scipy.fft.rfft2(v, workers=self.workers) * self.transfer, s=self.field_shape,
                                workers=self.workers)
