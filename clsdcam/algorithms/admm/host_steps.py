"""ADMM's steps on NumPy arrays: :class:`Splitting`, the iteration :mod:`clsdcam.algorithms.admm` derives, with both
passes and the c-step's solve along λ on cache-sized row blocks on the host's threads (``backends/blocks``): the
iteration reads each cube about twice besides its transforms. The first differences D_d and their adjoints, the
balance's RMS of the differences, and the tridiagonal sweeps along λ, are here too.

The data split on the sensor window. Outside the window the x-step is the relaxation alone (ξ = 0 there): x − ξ
becomes y = αHv + (1 − α)(x − ξ). So the host keeps x − ξ over the field as its spectrum Ŷ and steps it there, and x
and ξ on the window only: the c-step, having v̂, sets Ŷ ← αĤv̂ + (1 − α)Ŷ and transforms y back to the window alone,
into ``hv``; the x-step there reads Hv = (y − (1 − α)(x − ξ))/α and q = αHv + (1 − α)x + ξ = y + (2 − α)ξ, and
leaves in ``hv`` what x − ξ gained over y, x⁺ − ξ⁺ − y = (2 − α)ξ − 2ξ⁺ (x⁺ − ξ⁺ = q − 2ξ⁺); the next c-step adds
its transform to Ŷ. Both of those transforms are pruned to the window (``backends/host_fft``), where the kernels
transform the whole field, and the x-step skips the field outside the window. The iterates are the kernels' but for
rounding (tests/test_parity.py)."""
from __future__ import annotations

import math

import numpy as np
import scipy.fft

from ...backends import irfft2, irfft2_to_window, map_blocks, rfft2_of_window, scratch_buffer
from .margin import margin_correction
from .terms import CalibrationTerms, SplitState, SplittingBase

FFT_CHUNK_BYTES = 4 << 20     # spectrum bytes per chunk of bands in the transforms (host_convolution's)


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


def difference_rms(split: SplittingBase, w: np.ndarray) -> dict[int, float]:
    """rms(D_d w) for each of ``split``'s active TV axes (the balance's on the host, :mod:`.balance`): each band's
    differences in w's precision, their squares summed by one dot product a band and the bands' sums in float64. (The
    whole cube's squares formed in float64 at once took 0.5–2 s at full size on the host, docs/convergence.md, "The
    balance's time on a GPU"; this agrees with them to about 1e-6.)"""
    out = np.empty_like(w[:1])
    return {axis: math.sqrt(sum(band_squares(w, axis, band, out) for band in range(len(w))) / w.size)
            for axis in split.axes}


def band_squares(w: np.ndarray, axis: int, band: int, out: np.ndarray) -> float:
    """Σ(D_d w)² over one band of w (along λ: its difference to the next band, 0 for the last), ``out`` one band's
    scratch."""
    if axis == 0:
        if band == len(w) - 1:
            return 0.0
        np.subtract(w[band + 1], w[band], out=out[0])
    else:
        difference(w[band:band + 1], axis, out)
    flat = out.ravel()
    return float(np.dot(flat, flat))


def difference_adjoint_add(u: np.ndarray, axis: int, scale: float, out: np.ndarray, above=None,
                           scratch: dict | None = None) -> np.ndarray:
    """out += scale·D_dᵀu: (D_dᵀu)[i] = u[i − 1] − u[i] (along λ u[−1] = 0 and u[K−1] unused; along y the row
    ``above`` the first one may be given, a block of a cube's rows; else circular). scale·u is formed once, in
    the precision scale·u has (a float64 scale: float64), and subtracted and added shifted. Along x it is formed
    one element into each plane's run of rows, so that the run shifted by one is a view: after the subtraction,
    each row's first element there is put right (the row's last, circularly) and the whole run added in one pass."""
    k, n = u.shape[0], u.shape[axis]
    dtype = np.result_type(u, scale)
    if axis == 2:
        runs = np.empty((k, u[0].size + 1), dtype) if scratch is None else scratch_buffer(
            scratch, "scaled runs", (k, u[0].size + 1), dtype)
        out -= np.multiply(u, scale, out=runs[:, 1:].reshape(u.shape))
        runs[:, 0:-1:n] = runs[:, n::n]
        out += runs[:, :-1].reshape(u.shape)
        return out
    scaled = np.multiply(u, scale, out=np.empty(u.shape, dtype) if scratch is None else scratch_buffer(
        scratch, "scaled", u.shape, dtype))
    if axis == 0:
        out[:n - 1] -= scaled[:n - 1]
        out[1:] += scaled[:n - 1]
        return out
    out -= scaled
    out[:, 1:] += scaled[:, :n - 1]
    out[:, 0] += scaled[:, n - 1] if above is None else scale * above
    return out


def sweep_bands(g: np.ndarray, pivots: np.ndarray, coupling, scratch: dict) -> np.ndarray:
    """g ← v with (a·I + e·D_λᵀD_λ)v = g along axis 0, one system per (y, x), by Thomas's sweeps on the pivots m of
    :func:`~.terms.band_pivots` (e = ``coupling``, in g's real precision): forward g_j ← (g_j + e·g_{j−1})·m_j, back
    g_j ← g_j + (e·m_j)·g_{j+1}; each step one plane of the block (``kernels/admm.cl``'s admm_band_solve, in its
    order)."""
    g[0] *= pivots[0]
    if not coupling:
        g[1:] *= pivots[1:]
        return g
    term = scratch_buffer(scratch, "sweep term", g.shape[1:], g.dtype)
    factor = scratch_buffer(scratch, "sweep factor", pivots.shape[1:], pivots.dtype)
    for j in range(1, len(g)):
        g[j] += np.multiply(g[j - 1], coupling, out=term)
        g[j] *= pivots[j]
    for j in range(len(g) - 2, -1, -1):
        g[j] += np.multiply(g[j + 1], np.multiply(pivots[j], coupling, out=factor), out=term)
    return g


def relax(q: np.ndarray, previous: np.ndarray, alpha: float) -> np.ndarray:
    """q ← αq + (1 − α)·previous in place (nothing when α = 1): a split's over-relaxed point, α and 1 − α rounded
    to q's precision as the kernels round them."""
    if alpha != 1.0:
        alpha = q.dtype.type(alpha)
        q *= alpha
        q += (q.dtype.type(1) - alpha) * previous
    return q


class Splitting(SplittingBase):
    """ADMM's steps for one band-space problem (see the module docstring) on NumPy arrays, in row blocks on
    ``workers`` threads; ``b`` the normalised measurement."""

    def __init__(self, model, b: np.ndarray, terms: CalibrationTerms, tv=None, l1=None, workers: int = 1,
                 relaxation: float = 1.0, margin_steps: int = 0):
        super().__init__(model, terms, tv, l1, relaxation, margin_steps)
        self.workers = workers
        self.b = np.asarray(b, self.dtype)
        self.filters, self.transfer = terms.filters, terms.transfer
        self.chunk = max(1, FFT_CHUNK_BYTES // (self.field_shape[0] * (self.field_shape[1] // 2 + 1) *
                                                np.dtype(self.cdtype).itemsize))

    def set_penalties(self, penalties):
        """The penalties, what depends on them (the x-step's gains formed here, before the blocks' threads read them:
        :attr:`~.terms.PenaltyTerms.gain`), and the margin's correction of them (``margin_steps`` > 0)."""
        super().set_penalties(penalties)
        self._gain = self._penalty_terms.gain
        self.margin = margin_correction(self)

    # ---- the state -----------------------------------------------------------------------------------------
    def start(self, v0: np.ndarray) -> tuple[SplitState, float]:
        """The state from v = v0 with zero duals: Ŷ = Ĥv̂, and Hv on the window (K forward transforms and K pruned
        inverse ones), then every split's step unrelaxed (there is no previous split to relax towards); and the data
        term at v0."""
        cube, window = self.shape, (self.n_bands,) + self.sensor_shape
        spectrum, per_axis = (self.n_bands, self.field_shape[0], self.field_shape[1] // 2 + 1), (len(self.axes),) + cube
        zeros = np.zeros
        state = SplitState(v=np.array(v0, self.dtype), hv=zeros(window, self.dtype), x=zeros(window, self.dtype),
                           xi=zeros(window, self.dtype), rho=zeros(cube, self.dtype), w=zeros(cube, self.dtype),
                           eta=zeros(per_axis, self.dtype), s=zeros(per_axis, self.dtype), rest=zeros(cube, self.dtype),
                           spectra=(zeros(spectrum, self.cdtype), zeros(spectrum, self.cdtype)),
                           penalties=self.penalties, data_spectrum=zeros(spectrum, self.cdtype))
        self._rfft2(state.v, state.data_spectrum)
        state.data_spectrum *= self.transfer
        np.copyto(state.spectra[1], state.data_spectrum)
        self._irfft2_to_window(state.spectra[1], state.hv)
        data, _ = self.splits(state)
        return state, data

    # ---- one iteration -------------------------------------------------------------------------------------
    def c_step(self, state: SplitState) -> None:
        """v from the right-hand side the last splits left (x − ξ in Ŷ once the window's change in ``hv`` is added,
        the rest in ``rest``); Ŷ then the relaxed αĤv̂ + (1 − α)Ŷ, and ``hv`` its window (the module docstring); with
        the margin's correction (:mod:`.margin`) v̂ and Ŷ corrected before the inverse transforms."""
        solved, change = state.spectra
        self._window_rfft2(state.hv, change)
        self._add_tv_adjoint(state)
        self._rfft2(state.rest, solved)
        data_split = self.margin.data_split(state, change) if self.margin else None
        self._band_solve(state.data_spectrum, change, solved)       # Ŷ, and its copy in ``change``
        if self.margin:
            self.margin.correct(solved, (state.data_spectrum, change), data_split)
        self._irfft2(solved, state.v)
        self._irfft2_to_window(change, state.hv)

    def splits(self, state: SplitState, alpha: float = 1.0) -> tuple[float, tuple[float, float]]:
        """Every split's step and dual, relaxed by ``alpha`` (the last c-step's relaxation, or 1 after the start), on
        row blocks, and what the next c-step needs of them (the module docstring); the data term at v and the change
        of w."""
        k, hp, wp = self.shape
        parts = map_blocks(lambda y0, y1, scratch: self._split_block(state, y0, y1, scratch, alpha), hp,
                           k * wp * self.dtype.itemsize, self.workers)
        data, step, norm = (float(np.sum([p[i] for p in parts], dtype=np.float64)) for i in range(3))
        return data, (step, norm)

    # ---- the passes ----------------------------------------------------------------------------------------
    def _scalars(self, alpha: float) -> tuple:
        """α, 1 − α and 2 − α rounded to the cube's precision as the kernels round them."""
        one, a = self.dtype.type(1), self.dtype.type(alpha)
        return a, one - a, self.dtype.type(2) - a

    def _split_block(self, state: SplitState, y0: int, y1: int, scratch: dict, alpha: float):
        data = self._x_block(state, y0, y1, alpha)
        step, norm = self._w_block(state, y0, y1, scratch, alpha)
        self._u_block(state, y0, y1, scratch, alpha)
        return data, step, norm

    def _x_block(self, state: SplitState, y0: int, y1: int, alpha: float) -> float:
        """On the window's rows among y0…y1, from y = αHv + (1 − α)(x − ξ) in ``hv``: q = y + (2 − α)ξ; ξ⁺ = −f·(b −
        fᵀq)/(μ₁ + ‖f‖²), x ← q − ξ⁺, ``hv`` ← (2 − α)ξ − 2ξ⁺ (the module docstring), ξ ← ξ⁺. The data term
        ½‖fᵀHv − b‖² over those rows (at v, before the step), Hv = (y − (1 − α)(x − ξ))/α."""
        h = self.sensor_shape[0]
        if y0 >= h:
            return 0.0
        rows = slice(y0, min(y1, h))
        q, x, xi = state.hv[:, rows], state.x[:, rows], state.xi[:, rows]
        alpha, one_minus, two_minus = self._scalars(alpha)
        data = self._data_term((q - one_minus * (x - xi)) / alpha, rows)
        q += two_minus * xi
        misfit = self.b[rows] - np.einsum("khw,khw->hw", self.filters[:, rows], q)
        stepped = np.multiply(self._gain[:, rows], -misfit)
        np.subtract(q, stepped, out=x)
        np.multiply(xi, two_minus, out=q)
        q -= 2 * stepped
        xi[...] = stepped
        return data

    def _data_term(self, hv: np.ndarray, rows: slice) -> float:
        """½‖fᵀHv − b‖² over the window's ``rows`` (``hv`` those rows of Hv)."""
        residual = np.einsum("khw,khw->hw", self.filters[:, rows], hv) - self.b[rows]
        return 0.5 * float(np.vdot(residual.astype(np.float64), residual))

    def _w_block(self, state: SplitState, y0: int, y1: int, scratch: dict, alpha: float) -> tuple[float, float]:
        """q = αv + (1 − α)w + ρ; w ← max(q − τ₁/μ₃, 0); ρ ← q − w; rest ← μ₃(w − ρ); (‖w⁺ − w‖², ‖w⁺‖²) over the
        block."""
        p = self.penalties
        old = state.w[:, y0:y1]
        q = scratch_buffer(scratch, "q", old.shape, old.dtype)
        np.copyto(q, state.v[:, y0:y1])
        relax(q, old, alpha)
        q += state.rho[:, y0:y1]
        new = scratch_buffer(scratch, "w", q.shape, q.dtype)
        shift = self.nonneg_shift()
        np.subtract(q, shift, out=new) if shift else np.copyto(new, q)
        np.maximum(new, 0, out=new)
        change = np.subtract(old, new, out=scratch_buffer(scratch, "change", q.shape, q.dtype))
        step = float(np.vdot(change.ravel(), change.ravel()))    # contiguous: ravel is a view, not a copy
        old[...] = new
        rho = np.subtract(q, new, out=state.rho[:, y0:y1])
        rest = np.subtract(new, rho, out=state.rest[:, y0:y1])
        rest *= p.nonneg
        return step, float(np.vdot(new.ravel(), new.ravel()))

    def _u_block(self, state: SplitState, y0: int, y1: int, scratch: dict, alpha: float) -> None:
        """q = αD_d v + (1 − α)u_d + η_d, with u_d = s_d + η_d (so q = αD_d v + (1 − α)s_d + (2 − α)η_d);
        η_d ← clip(q, ±τw_d/μ₂); s_d ← q − 2η_d, per active axis."""
        v = state.v
        q = scratch_buffer(scratch, "q", (self.n_bands, y1 - y0, self.shape[2]), self.dtype)
        for i, axis in enumerate(self.axes):
            block = v[:, y0:y1]
            if axis == 1:
                difference(block, 1, q, below=v[:, y1 % self.shape[1]])
            else:
                difference(block, axis, q)
            eta, s = state.eta[i, :, y0:y1], state.s[i, :, y0:y1]
            relax(q, s, alpha)
            q += (self.dtype.type(2) - self.dtype.type(alpha)) * eta if alpha != 1.0 else eta
            threshold = self.threshold(axis)
            np.clip(q, -threshold, threshold, out=eta)
            np.subtract(q, eta, out=s)
            s -= eta

    def _add_tv_adjoint(self, state: SplitState) -> None:
        """rest += Σ_d μ₂,d·D_dᵀs_d on row blocks."""
        k, hp, wp = self.shape
        if self.axes:
            map_blocks(lambda y0, y1, scratch: self._adjoint_block(state, y0, y1, scratch), hp,
                       k * wp * self.dtype.itemsize, self.workers)

    def _adjoint_block(self, state: SplitState, y0: int, y1: int, scratch: dict) -> None:
        """rest += Σ_d μ₂,d·D_dᵀs_d on rows y0…y1 (along y with the row above the block)."""
        out = state.rest[:, y0:y1]
        for i, axis in enumerate(self.axes):
            s = state.s[i]
            above = s[:, (y0 - 1) % self.shape[1]] if axis == 1 else None
            difference_adjoint_add(s[:, y0:y1], axis, self.penalties.tv_along(axis), out, above=above,
                                   scratch=scratch)

    def rescale_tv_duals(self, state: SplitState, ratios: dict) -> None:
        """s_d ← s_d + (1 − r_d)η_d, η_d ← r_d·η_d for each active axis d, r_d = ``ratios[d]`` (:mod:`.balance`)."""
        for i, axis in enumerate(self.axes):
            r = self.dtype.type(ratios[axis])
            state.s[i] += (self.dtype.type(1) - r) * state.eta[i]
            state.eta[i] *= r

    def difference_rms(self, state: SplitState) -> dict[int, float]:
        """rms(D_d w) of the iterate for each active TV axis (:func:`difference_rms`; :mod:`.balance`)."""
        return difference_rms(self, state.w)

    def _band_solve(self, data: np.ndarray, change: np.ndarray, rest: np.ndarray) -> None:
        """data += change; rest ← v̂, the system along λ at each Fourier coefficient for the right-hand side
        μ₁conj(Ĥ)·data + rest (:func:`sweep_bands`); data ← α·Ĥv̂ + (1 − α)·data (α the relaxation), and ``change``
        a copy of it (for the transform to the window, which spends it); on row blocks of the spectra."""
        k, rows, cols = data.shape
        coupling = self.dtype.type(self.coupling)
        alpha, one_minus, _ = self._scalars(self.relaxation)

        def block(y0, y1, scratch):
            spectrum, kept = rest[:, y0:y1], data[:, y0:y1]
            kept += change[:, y0:y1]
            product = scratch_buffer(scratch, "product", kept.shape, kept.dtype)
            spectrum += np.multiply(kept, self._data_transfer[y0:y1], out=product)
            sweep_bands(spectrum, self._pivots[:, y0:y1], coupling, scratch)
            hv = np.multiply(spectrum, self.transfer[y0:y1], out=product)
            if alpha == 1:
                np.copyto(kept, hv)
            else:
                kept *= one_minus
                hv *= alpha
                kept += hv
            np.copyto(change[:, y0:y1], kept)

        map_blocks(block, rows, k * cols * data.itemsize, self.workers)

    def _chunks(self):
        """The bands in chunks whose spectra fit the cache, as slices."""
        return (slice(k0, k0 + self.chunk) for k0 in range(0, self.n_bands, self.chunk))

    def _rfft2(self, x: np.ndarray, out: np.ndarray) -> None:
        for bands in self._chunks():
            out[bands] = scipy.fft.rfft2(x[bands], workers=self.workers)

    def _irfft2(self, spectrum: np.ndarray, out: np.ndarray) -> None:
        """out ← irfft2(spectrum), the spectrum overwritten (the c-step's, spent once transformed back)."""
        for bands in self._chunks():
            out[bands] = irfft2(spectrum[bands], self.field_shape, self.workers, overwrite=True)

    def _irfft2_to_window(self, spectrum: np.ndarray, out: np.ndarray) -> None:
        """out ← the sensor window of irfft2(spectrum) (pruned), the spectrum overwritten."""
        for bands in self._chunks():
            out[bands] = irfft2_to_window(spectrum[bands], self.field_shape, self.sensor_shape, self.workers,
                                          overwrite=True)

    def _window_rfft2(self, window: np.ndarray, out: np.ndarray) -> None:
        """out ← rfft2 of ``window`` zero-padded to the field (pruned)."""
        for bands in self._chunks():
            out[bands] = rfft2_of_window(window[bands], self.field_shape, self.workers)

    # ---- the data split over the field (tools that read or set the splits as a whole) ------------------------
    def data_split(self, state: SplitState) -> np.ndarray:
        """x over the field after the splits: x − ξ from Ŷ and the window's change in ``hv``, plus ξ on the
        window."""
        x = irfft2(state.data_spectrum.copy(), self.field_shape, self.workers, overwrite=True).astype(self.dtype)
        h, w = self.sensor_shape
        x[:, :h, :w] += state.hv + state.xi
        return x

    def set_data_split(self, state: SplitState, x: np.ndarray, xi: np.ndarray) -> None:
        """The data split x over the field and its dual ξ on the window, as the splits leave them: Ŷ = rfft2(x − ξ),
        nothing left in ``hv``."""
        h, w = self.sensor_shape
        state.xi[...] = xi
        state.margin_band = None
        state.x[...] = x[:, :h, :w]
        y = np.array(x, self.dtype)
        y[:, :h, :w] -= state.xi
        self._rfft2(y, state.data_spectrum)
        state.hv[...] = 0

    def convolve(self, v: np.ndarray) -> np.ndarray:
        """Hv = irfft2(Ĥ·rfft2(v)) over the field (2K transforms; the tools' and tests' whole Hv)."""
        return irfft2(scipy.fft.rfft2(v, workers=self.workers) * self.transfer, self.field_shape, self.workers,
                      overwrite=True)
