"""The c-step's correction for the field's margin (the host's steps and the kernels'): a few conjugate-gradient steps,
on the field's lowest frequencies, towards the c-step with the data split's unobserved part eliminated.
docs/convergence.md ("Where the road left lies", "The margin's correction built") has the measurements.

Why. ADMM splits x = Hv over the whole field, so that its c-step is diagonal in Fourier. Outside the sensor window
no data bind x (ξ = 0 there), and the c-step's μ₁/2‖Hv − (x − ξ)‖² over that margin only pulls Hv back towards its
last value: an inertia on smooth light, which the PSF spreads nearly alike from the window and the margin, so that
light drains from the margin into the window over hundreds of iterations. Minimised over x in the margin as well as
over v, that term vanishes, and the c-step is the masked system (M the window)

    A v = (μ₁HᵀMH + μ₂ΣD_dᵀD_d + μ₃I) v = μ₁HᵀM(x − ξ) + rest,      A = P − μ₁Hᵀ(I − M)H,

P = μ₁HᵀH + μ₂ΣD_dᵀD_d + μ₃I the c-step's own matrix, solved exactly in Fourier. From the c-step's v₀ = P⁻¹(μ₁Hᵀ(x −
ξ) + rest), the masked system's residual is r₀ = μ₁Hᵀ(I − M)(Hv₀ − x) (ξ = 0 in the margin), and ``steps`` of
conjugate gradients preconditioned by P⁻¹ give a correction δ: v ← v₀ + δ, and the relaxed data split Ŷ ← Ŷ + αĤδ̂.

Where. The slow part is smooth light (about 60 numbers of a 128×160×64 cube), so δ is sought among the field's
lowest frequencies alone, |k_y| < B_y and |k_x| < B_x (:data:`BAND`; :class:`Band`), by the Galerkin system there:
ΠAΠ = ΠPΠ − μ₁Ĥ*(I − T)Ĥ, with T = ΠMΠ the window's mask seen on the band. The window is a rectangle at the
origin, so T is the Kronecker product of two small matrices, one per axis, T_y[k, k′] = (1/Hp)Σ_{n<h} e^(−2πi(k−k′)n/Hp)
(and T_x alike): each application two small matrix products a band, no transform. The residual is r₀'s band with
the mask's leakage from higher frequencies left out, μ₁Ĥ*(I − T)·band(Ĥv̂₀ − x̂); for it, the Galerkin system's
solution is the masked correction's A-orthogonal projection onto the band, which cannot overshoot it in A's norm (a
coarse grid's own mask, tried first, made the iteration diverge on a small field). It needs only what the c-step has
before its inverse transforms: v̂₀, and x̂ = Ŷ + rfft2(hv) + Ξ (Ŷ with the window's change), with Ξ the band of ξ's
spectrum (its window zero-padded), tracked from the window transform the c-step makes anyway. After the splits' step
``hv`` holds (2 − α)ξ − 2ξ⁺, so

    Ξ⁺ = ((2 − α)Ξ − rfft2(hv)) / 2,

a recursion whose rounding decays by (2 − α)/2 an iteration; it starts from a pruned transform of ξ wherever
anything but the splits set ξ (``SplitState.margin_band`` None). The correction adds to the band of v̂ and Ŷ, before
the c-step's inverse transforms: it costs no field transform.

On the kernels (:class:`~.kernel_steps.KernelSplitting`) the x-step leaves x⁺ − ξ⁺ in ``hv`` over the whole field,
from its relaxed point q = αHv + (1 − α)x + ξ (ξ = 0 outside the window): hv⁺ = q − 2ξ⁺ everywhere. So the band of
rfft2(hv), D, and the band Q of q's spectrum give

    Ξ⁺ = (Q − D) / 2,   x̂⁺ = D + Ξ⁺,   and the next   Q⁺ = αĤv̂ + (1 − α)x̂⁺ + Ξ⁺   (v̂ corrected),

the same decay of rounding. The kernels track Q (``SplitState.margin_band``, on the device) and do the correction's
arithmetic on the device too, in kernels of their own (:mod:`.margin_kernels`) from :class:`MarginCorrection`'s
terms: the x-step relaxes Hv itself, so Ĥv̂ is written unrelaxed.

Exact. At a fixed point of the corrected iteration x = Hv over the field, so Hv₀ − x = −Hδ and r₀ is linear in δ:
δ = 0 there, and the fixed point is the plain c-step's, the problem's minimiser, whatever the band.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import scipy.fft

from ...backends import rfft2_of_window, single_threaded_blas
from .terms import band_coupling, band_diagonal, difference_spectrum

BAND = (8, 10)     # the correction's frequencies |k_y| < 8, |k_x| < 10 cycles over the field (fewer on a small one)


def window_mask_matrix(frequencies: np.ndarray, length: int, window: int) -> np.ndarray:
    """T[k, k′] = (1/N)Σ_{n<h} e^(−2πi(k−k′)n/N) for the signed ``frequencies`` k, k′ of a length-N axis whose first
    h = ``window`` samples are the window: the mask's product seen in Fourier, (Mz)^_k = Σ_k′ T[k, k′] ẑ_k′."""
    n = np.arange(window)
    shifts = frequencies[:, None] - frequencies[None, :]
    return np.exp(-2j * np.pi * shifts[..., None] * n / length).sum(axis=-1) / length


class Band:
    """The field's lowest frequencies |k_y| < b_y, 0 ≤ k_x < b_x of its half spectrum (…, Hp, Wp//2 + 1), the rows
    in signed order −(b_y − 1)…b_y − 1 (b_y ≤ Hp/2 and b_x ≤ Wp/2, so that no Nyquist frequency is among them), and
    the window's mask T = T_y ⊗ T_x on them (:func:`window_mask_matrix`)."""

    def __init__(self, field_shape, window_shape, band=BAND, dtype=np.complex128):
        (hp, wp), (h, w) = field_shape, window_shape
        by, bx = min(band[0], hp // 2), min(band[1], wp // 2)
        self.rows, self.columns = np.arange(1 - by, by), bx
        self._field_rows = self.rows % hp
        self.mask_y = window_mask_matrix(self.rows.astype(float), hp, h).astype(dtype)
        self.mask_x = window_mask_matrix(np.arange(1 - bx, bx).astype(float), wp, w).T[:, bx - 1:].astype(dtype)

    def take(self, spectrum: np.ndarray) -> np.ndarray:
        """The band of ``spectrum`` (a copy)."""
        return spectrum[..., self._field_rows, :self.columns]

    def add(self, spectrum: np.ndarray, band: np.ndarray) -> None:
        """spectrum += ``band`` zero-padded to the field's half spectrum, in place."""
        spectrum[..., self._field_rows, :self.columns] += band

    def real(self, z: np.ndarray) -> np.ndarray:
        """z with its column k_x = 0 made Hermitian along k_y, (z_k + conj z_−k)/2, in place: the band of a real
        field's spectrum. An inverse real transform drops the rest, so a correction must not carry it: on the kernels
        the next c-step's band is tracked from the corrected Ĥv̂, and a part the field never had, fed back through the
        correction, grew ×100 an iteration."""
        column = z[..., :, 0]
        column += np.conj(column[..., ::-1])
        column *= column.real.dtype.type(0.5)
        return z

    def masked(self, z: np.ndarray) -> np.ndarray:
        """T·z on the band (z of shape (K, rows, columns)): z's columns k_x < 0 from Hermitian symmetry (ẑ_{−k} =
        conj ẑ_k), then T_y z T_xᵀ's columns k_x ≥ 0, as two matrix products over every band at once."""
        whole = np.concatenate([np.conj(z[..., ::-1, :0:-1]), z], axis=-1)
        k, rows, width = whole.shape
        across = (whole.reshape(k * rows, width) @ self.mask_x).reshape(k, rows, self.columns)
        down = self.mask_y @ across.transpose(1, 0, 2).reshape(rows, k * self.columns)
        return down.reshape(rows, k, self.columns).transpose(1, 0, 2)


@lru_cache(maxsize=8)
def field_band(field_shape: tuple, window_shape: tuple, band: tuple, dtype: np.dtype) -> Band:
    """The :class:`Band` of a field and its window, built once a process for each: its masks' sums are penalty-free
    and cost about 25 ms at full size (64 × 640 × 896, on a 2-core machine), where a solve builds its correction twice
    (the camera's penalties, then the balanced ones) and a video's frames again. Shared, so its arrays are read-only."""
    shared = Band(field_shape, window_shape, band, dtype)
    for array in vars(shared).values():
        if isinstance(array, np.ndarray):
            array.flags.writeable = False
    return shared


def path_eigenvalues(n_bands: int) -> np.ndarray:
    """The eigenvalues 2 − 2cos(πj/K), j = 0…K − 1, of D_λᵀD_λ (:func:`~.terms.band_degrees` its diagonal, −1 its
    off-diagonals), whose eigenvectors are the DCT-II's: the circular difference's spectrum on 2K points, its first
    K (the path with free ends is the circle of its mirror image)."""
    return difference_spectrum(2 * n_bands)[:n_bands]


def margin_correction(split) -> "MarginCorrection | None":
    """The correction of ``split``'s penalties, built from its host terms (None with no ``margin_steps``)."""
    return MarginCorrection(split, split.margin_steps) if split.margin_steps > 0 else None


class MarginCorrection:
    """ΠAΠ and P⁻¹ of one splitting's penalties on the band, and the correction they make (the module docstring);
    built again for new penalties (each splitting's ``set_penalties``, before its terms go to a device)."""

    def __init__(self, split, steps: int, band=BAND):
        p, axes, k = split.penalties, split.axes, split.n_bands
        self.steps, self.relaxation, self.workers = int(steps), split.relaxation, split.workers
        self.field_shape = split.field_shape
        self.band = field_band(tuple(split.field_shape), tuple(split.sensor_shape), tuple(band), np.dtype(split.cdtype))
        self.transfer = self.band.take(split.terms.transfer)
        self.data_transfer = self.band.take(split._data_transfer)   # the c-step's own host terms, of the same penalties
        diagonal = self.band.take(band_diagonal(p, axes, split.terms.transfer_power, split.field_shape))
        modes = diagonal + band_coupling(p, axes) * path_eigenvalues(k)[:, None, None]     # P in the modes
        self.diagonal, self.inverse = modes.astype(split.dtype), (1 / modes).astype(split.dtype)
        self.weights = np.full(self.band.columns, 2.0, split.dtype)
        self.weights[0] = 1.0

    # ---- the data split's band -----------------------------------------------------------------------------
    def data_split(self, state, change: np.ndarray) -> np.ndarray:
        """x̂'s band on the host, Ŷ + rfft2(hv) + Ξ (``change`` = rfft2(hv), not yet added to Ŷ), Ξ tracked in
        ``state.margin_band`` (the module docstring)."""
        fresh = self.band.take(change)
        if state.margin_band is None:
            state.margin_band = self.dual_band(state.xi)
        else:
            state.margin_band *= state.margin_band.real.dtype.type((2 - self.relaxation) / 2)
            state.margin_band -= fresh / 2
        fresh += self.band.take(state.data_spectrum)
        fresh += state.margin_band
        return fresh

    def dual_band(self, xi: np.ndarray) -> np.ndarray:
        """Ξ: the band of ξ's spectrum, its window zero-padded (a pruned transform)."""
        return self.band.take(rfft2_of_window(np.asarray(xi), self.field_shape, self.workers))

    # ---- the correction ------------------------------------------------------------------------------------
    def correct(self, solved: np.ndarray, relaxed: tuple, data_split: np.ndarray) -> None:
        """On the host: v̂ (``solved``) += δ̂, and each of the ``relaxed`` spectra (Ŷ and its copy) += αĤδ̂, from v̂₀ =
        ``solved`` and x̂'s band ``data_split`` (:meth:`data_split`)."""
        delta = self.correction(self.band.take(solved), data_split)
        self.band.add(solved, delta)
        delta *= self.transfer
        delta *= delta.real.dtype.type(self.relaxation)
        for spectrum in relaxed:
            self.band.add(spectrum, delta)

    def correction(self, solved: np.ndarray, data_split: np.ndarray) -> np.ndarray:
        """δ̂ on the band from v̂₀'s band ``solved`` and x̂'s ``data_split``: ``steps`` P⁻¹-preconditioned conjugate
        gradients on ΠAΠ·δ̂ = μ₁Ĥ*(I − T)(Ĥv̂₀ − x̂), the masked system's residual r₀ on the band; its column k_x = 0
        then made Hermitian along k_y (:meth:`Band.real`). Worked in the modes along λ (:meth:`_modes`), and BLAS
        on one thread: its products are small (a threaded OpenBLAS took 10× as long on a busy machine)."""
        with single_threaded_blas():
            apart = self._modes(self.transfer * solved - data_split)
            return self.band.real(self._bands(self._solve(self._pulled(apart))))

    def _modes(self, z: np.ndarray) -> np.ndarray:
        """z along λ in the orthonormal DCT-II's modes. D_λᵀD_λ (the path's Laplacian, its ends free) is diagonal
        there (:func:`path_eigenvalues`), and so is P = a + e·D_λᵀD_λ at each coefficient, where in the bands it is
        tridiagonal; Ĥ, μ₁Ĥ* and T act alike on every band, so they commute with the transform, and it keeps the
        inner product: the conjugate gradients run there unchanged, P⁻¹ a product."""
        return scipy.fft.dct(z, type=2, axis=0, norm="ortho", workers=self.workers)

    def _bands(self, z: np.ndarray) -> np.ndarray:
        """:meth:`_modes` undone (``z`` spent)."""
        return scipy.fft.idct(z, type=2, axis=0, norm="ortho", overwrite_x=True, workers=self.workers)

    def _pulled(self, z: np.ndarray) -> np.ndarray:
        """μ₁Ĥ*(I − T)·z on the band."""
        return self.data_transfer * (z - self.band.masked(z))

    def _apply(self, v: np.ndarray) -> np.ndarray:
        """ΠAΠ·v̂ = P·v̂ − μ₁Ĥ*(I − T)Ĥ·v̂ in the modes (P diagonal there)."""
        out = self.diagonal * v
        out -= self._pulled(self.transfer * v)
        return out

    def _precondition(self, r: np.ndarray) -> np.ndarray:
        """P⁻¹·r̂ in the modes."""
        return r * self.inverse

    def _dots(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """⟨a, b⟩ for each mode along λ (axis 0), of the real fields whose half spectra's bands a and b are (up to the
        transform's constant), in float64: shape (K,)."""
        weighted = (a * self.weights).astype(np.complex128)
        return np.einsum("krc,krc->k", weighted.conj(), b.astype(np.complex128)).real

    def _solve(self, r: np.ndarray) -> np.ndarray:
        """δ̂ after ``steps`` of P⁻¹-preconditioned conjugate gradients on A·δ̂ = r̂ from 0, in the modes, each mode its
        own: A is block diagonal there (P is diagonal, and Ĥ, μ₁Ĥ* and T act on each mode's plane alone), so every
        mode's gradients run on its own (rows × columns) system, with its own step lengths. Over the same steps each
        mode's error in A's norm is then at most what one set of lengths for the whole band leaves (each mode's
        Krylov space holds that iteration's), and on the kernels each mode is one work group, its plane in local
        memory. A mode whose rz is not positive (its residual zero) stops where it is."""
        delta, z = np.zeros_like(r), self._precondition(r)
        p, rz = z, self._dots(r, z)
        for step in range(self.steps):
            live = rz > 0
            if not live.any():
                break
            ap = self._apply(p)
            length = np.divide(rz, self._dots(p, ap), out=np.zeros_like(rz), where=live)
            delta += np.where(live[:, None, None], self._per_mode(length) * p, 0)      # a stopped mode stays put
            if step + 1 == self.steps:
                break
            r = r - self._per_mode(length) * ap
            z = self._precondition(r)
            rz, last = self._dots(r, z), rz
            p = z + self._per_mode(np.divide(rz, last, out=np.zeros_like(rz), where=live)) * p
        return delta

    def _per_mode(self, values: np.ndarray) -> np.ndarray:
        """One float64 number a mode as the band's precision, shaped to scale each mode's plane."""
        return values.astype(self.diagonal.dtype)[:, None, None]
