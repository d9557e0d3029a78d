"""What ADMM's steps share on every backend (:mod:`clsdcam.algorithms.admm`): the penalties, the state's arrays,
the calibration's terms (built once per solver and kept in its shared store) and the base of the steps, with the
problem's scales the penalties are set from."""
from __future__ import annotations

from dataclasses import astuple, dataclass, fields, replace
from functools import cached_property

import numpy as np


TERMS_KEY = "admm calibration terms"     # the solver's shared store keeps the CalibrationTerms under this name


@dataclass(frozen=True)
class Penalties:
    """μ₁ (data split), μ₂ (TV split), μ₃ (non-negativity split), absolute; the TV split's along axis d (0: λ, 1: y,
    2: x) is μ₂,d = μ₂·β_d, ``tv_balance`` the β_d (None, every β_d 1, until :mod:`.balance` sets them)."""

    data: float
    tv: float
    nonneg: float
    tv_balance: tuple | None = None

    def tv_along(self, axis: int) -> float:
        """μ₂,d."""
        return self.tv if self.tv_balance is None else self.tv * self.tv_balance[axis]

    def scaled(self, factor: float) -> "Penalties":
        """Every penalty times ``factor`` (the β_d kept)."""
        return replace(self, data=self.data * factor, tv=self.tv * factor, nonneg=self.nonneg * factor)


@dataclass
class SplitState:
    """ADMM's arrays: v and Hv (the c-step's; Hv then holds x − ξ), x (the data split, kept for the relaxation;
    on the host for the data term, its relaxation taken in Ŷ),
    ξ on the sensor window, ρ, w (the iterate), η_d and s_d = u_d − η_d per active TV axis, the right-hand side's
    rest, the two spectra the c-step works in; and the penalties the scaled duals are in (a video's next frame resumes
    with them). The host's steps keep the data split on the sensor window (:class:`~.host_steps.Splitting`): x and ξ
    there, x − ξ over the field as its spectrum ``data_spectrum`` (None on the kernels), and in ``hv`` the window of
    its relaxed point after the c-step, the window's change to it after the splits; with the margin's correction
    (:mod:`.margin`), ``margin_band`` what it tracks on the field's lowest frequencies: the band of ξ's spectrum on
    the host, of the x-step's relaxed point's on the kernels (None where anything but the splits set ξ; on the steps'
    own side, host or device, and not among :meth:`arrays`)."""

    v: np.ndarray
    hv: np.ndarray
    x: np.ndarray
    xi: np.ndarray
    rho: np.ndarray
    w: np.ndarray
    eta: np.ndarray
    s: np.ndarray
    rest: np.ndarray
    spectra: tuple
    penalties: Penalties | None = None
    data_spectrum: object = None
    margin_band: object = None

    def arrays(self) -> list:
        """Every array of the state but the c-step's spectra (what a resumed solve scales into its units)."""
        kept = (getattr(self, f.name) for f in fields(self) if f.name not in ("spectra", "penalties", "margin_band"))
        return [array for array in kept if array is not None]

    def moved(self) -> Penalties | None:
        """What of the state a frame whose field was moved under it resumes from (a drifting video's,
        :func:`clsdcam.batch.motion.predict_state`): the penalties, balanced and told the probe's reading, and not the
        splits and duals, which belong to the unmoved field."""
        return self.penalties


def band_degrees(n_bands: int) -> np.ndarray:
    """The diagonal of D_λᵀD_λ for the first differences along λ (the last one 0): the path graph's degrees
    1, 2, …, 2, 1 (0 for one band); its off-diagonals are −1."""
    degrees = np.full(n_bands, 2.0)
    degrees[0] -= 1.0                      # one band: 2 − 1 − 1 = 0
    degrees[-1] -= 1.0
    return degrees


def band_pivots(diagonal: np.ndarray, coupling: float, n_bands: int) -> np.ndarray:
    """Thomas's reciprocal pivots of the tridiagonal systems (a·I + e·D_λᵀD_λ)v = r along the bands, one per entry
    a of ``diagonal`` (e = ``coupling``), in float64, shape (K,) + diagonal's:

        m_0 = 1/(a + e·deg_0),   m_j = 1/(a + e·deg_j − e²·m_{j−1});

    the solve is then g_j = (r_j + e·g_{j−1})·m_j forward and v_j = g_j + e·m_j·v_{j+1} back. With a > 0 the
    system is strictly diagonally dominant: every denominator but the last exceeds e (by induction, e·m_{j−1} < 1),
    so e·m_j < 1 for j < K − 1 and no pivoting is needed; a rounding error passes from one band to the next with a
    weight below 1. The last pivot, between about 1/(a + e) (a ≫ e) and 1/(K·a) (a ≪ e), carries the system's own
    conditioning."""
    degrees = band_degrees(n_bands)
    pivots = np.empty((n_bands,) + np.shape(diagonal))
    pivots[0] = 1.0 / (diagonal + coupling * degrees[0])
    for j in range(1, n_bands):
        pivots[j] = 1.0 / (diagonal + coupling * degrees[j] - coupling * coupling * pivots[j - 1])
    return pivots


def band_coupling(p: Penalties, axes) -> float:
    """e = μ₂,λ, the c-step's coupling between neighbouring bands (0 without TV along λ)."""
    return p.tv_along(0) if 0 in axes else 0.0


def band_diagonal(p: Penalties, axes, transfer_power: np.ndarray, field_shape) -> np.ndarray:
    """a = μ₁|Ĥ|² + μ₂,y|d̂_y|² + μ₂,x|d̂_x|² + μ₃ over the (Hp, Wp) field's half spectrum (``transfer_power`` |Ĥ|²;
    TV's terms on ``axes`` only): the diagonal of the c-step's system along λ at each Fourier coefficient."""
    hp, wp = field_shape
    spatial = p.data * transfer_power
    if 1 in axes:
        spatial = spatial + p.tv_along(1) * difference_spectrum(hp)[:, None]
    if 2 in axes:
        spatial = spatial + p.tv_along(2) * difference_spectrum(wp, half=True)[None, :]
    return spatial + p.nonneg


def difference_spectrum(n: int, half: bool = False) -> np.ndarray:
    """|d̂(k)|² = 2 − 2cos(2πk/n) of the circular forward difference (k < n//2 + 1 when ``half``)."""
    k = np.arange(n // 2 + 1 if half else n)
    return 2.0 - 2.0 * np.cos(2.0 * np.pi * k / n)


def x_step_reciprocal(filter_energy: np.ndarray, data_penalty: float, dtype) -> np.ndarray:
    """r_p = 1/(μ₁ + ‖f_p‖²) over the (H, W) sensor, formed in float64 and rounded to ``dtype`` once: the x-step's
    gains are g_p = f_p·r_p, the product in the filters' precision (one rounding an element), on the host
    (:attr:`PenaltyTerms.gain`) and inline on the kernels alike."""
    return (1.0 / (data_penalty + filter_energy)).astype(dtype)


@dataclass(eq=False)
class PenaltyTerms:
    """The terms of one set of penalties (:meth:`CalibrationTerms.for_penalties`): the x-step's ``reciprocal`` r
    (:func:`x_step_reciprocal`) of the calibration's ``filters`` f, ``data_transfer`` μ₁conj(Ĥ), and the c-step's system
    along λ, its ``diagonal`` a = μ₁|Ĥ|² + μ₂,y|d̂_y|² + μ₂,x|d̂_x|² + μ₃ (:func:`band_diagonal`, float64) and
    ``coupling`` e = μ₂,λ. The host's gains f·r (:attr:`gain`) and pivots of a and e (:attr:`pivots`) are formed on
    first use, so that the kernels, which form the gains inline and their pivots on the device, never pay for
    them."""

    reciprocal: np.ndarray
    filters: np.ndarray
    data_transfer: np.ndarray
    diagonal: np.ndarray
    coupling: float
    n_bands: int
    dtype: np.dtype

    @cached_property
    def gain(self) -> np.ndarray:
        """The x-step's gains g = f·r (K, H, W), in the filters' precision."""
        return self.filters * self.reciprocal

    @cached_property
    def pivots(self) -> np.ndarray:
        """:func:`band_pivots` of a and e (a float64 recursion over the whole spectrum), in the working precision."""
        return band_pivots(self.diagonal, self.coupling, self.n_bands).astype(self.dtype)


class CalibrationTerms:
    """What the steps need of one model's calibration alone, the filters f_p with their energies ‖f_p‖² and the
    transfer function Ĥ with |Ĥ|², and of the penalties, their :class:`PenaltyTerms`: built once and kept by the
    solver, so a video's frames do not rebuild them; the terms of the last penalties are kept, and on a device the
    arrays made of them (:meth:`on_device`)."""

    def __init__(self, model, filters: np.ndarray):
        self.dtype = np.dtype(model.backend.dtype)
        self.cdtype = np.result_type(self.dtype, np.complex64)
        self.field_shape, self.n_bands = model.field_shape, model.n_bands
        self.filters = np.ascontiguousarray(filters, self.dtype)
        self.filter_energy = np.einsum("khw,khw->hw", self.filters, self.filters, dtype=np.float64)
        self.transfer = model.transfer.astype(self.cdtype)
        self.transfer_power = np.abs(self.transfer.astype(np.complex128)) ** 2
        self._last = None           # ((penalties, TV axes), their PenaltyTerms)
        self._uploads: dict = {}    # term name -> (backend, the host array it is made from, the device array)

    def for_penalties(self, p: Penalties, axes) -> PenaltyTerms:
        """The :class:`PenaltyTerms` of ``p``, TV's terms on ``axes`` only (those of the last penalties kept)."""
        key = (astuple(p), tuple(axes))
        if self._last is None or self._last[0] != key:
            self._last = (key, self._penalty_terms(p, axes))
        return self._last[1]

    def on_device(self, backend, name: str, host: np.ndarray, complex_: bool = False):
        """``host``, the term called ``name``, on ``backend``'s device: uploaded once, and again only when the backend
        or the host array (new penalties, new terms) is another."""
        return self.made_on_device(backend, name, host, lambda: backend.to_device(host, complex_))

    def made_on_device(self, backend, name: str, source: np.ndarray, make):
        """The device array ``make()`` makes of the host array ``source``, the term called ``name``: made once, and
        again only when the backend or ``source`` is another."""
        kept = self._uploads.get(name)
        if kept is None or kept[0] is not backend or kept[1] is not source:
            kept = (backend, source, make())
            self._uploads[name] = kept
        return kept[2]

    def _penalty_terms(self, p: Penalties, axes) -> PenaltyTerms:
        return PenaltyTerms(reciprocal=x_step_reciprocal(self.filter_energy, p.data, self.dtype),
                            filters=self.filters, data_transfer=(p.data * np.conj(self.transfer)).astype(self.cdtype),
                            diagonal=band_diagonal(p, axes, self.transfer_power, self.field_shape),
                            coupling=band_coupling(p, axes), n_bands=self.n_bands, dtype=self.dtype)


class SplittingBase:
    """What ADMM's steps share on every backend: the problem's shapes and scales, and the penalties with what depends
    on them. ``model``: the band space's :class:`~clsdcam.camera.model.ForwardModel`; ``terms`` its
    :class:`CalibrationTerms`; ``tv`` the :class:`~clsdcam.solve.priors.TotalVariation` prior or None, ``l1`` the
    :class:`~clsdcam.solve.priors.Sparsity` prior or None (their weights are read at every step: an automatic weight
    chosen mid-solve takes effect at once); ``relaxation`` α, each split's over-relaxation (the module docstring of
    :mod:`clsdcam.algorithms.admm`; 1: none); ``margin_steps`` the conjugate-gradient steps of the margin's
    correction (:mod:`.margin`; 0: none). A backend's steps (:class:`Splitting` on NumPy,
    :class:`~clsdcam.algorithms.admm.kernel_steps.KernelSplitting` with programs) add ``start``, ``c_step``, ``splits``
    and ``difference_rms`` (the balance's)."""

    def __init__(self, model, terms: CalibrationTerms, tv=None, l1=None, relaxation: float = 1.0,
                 margin_steps: int = 0):
        self.terms = terms
        self.relaxation, self.margin_steps = relaxation, margin_steps
        self.margin = None           # the margin's correction of the penalties (a subclass's set_penalties)
        self.dtype, self.cdtype = terms.dtype, terms.cdtype
        self.field_shape = model.field_shape
        self.sensor_shape = model.sensor_shape
        self.shape = model.cube_shape
        self.n_bands = model.n_bands
        self.tv, self.l1 = tv, l1
        self.axes = [axis for axis, weight in enumerate(tv.axis_weights) if weight > 0] if tv is not None else []
        self.penalties: Penalties | None = None
        self._penalty_terms: PenaltyTerms | None = None      # the penalties' terms (set_penalties)

    # ---- the problem's scales ------------------------------------------------------------------------------
    @property
    def data_curvature(self) -> float:
        """The mean of ‖f_p‖² over the sensor: the x-step's curvature from the data term."""
        return float(np.mean(self.terms.filter_energy))

    @property
    def transfer_peak(self) -> float:
        """max |Ĥ|² (the DC gain squared for a non-negative PSF)."""
        return float(self.terms.transfer_power.max())

    @property
    def transforms(self) -> int:
        """2-D FFTs an iteration does: 2K forward and 2K inverse in the c-step, every band (none is skipped; on the
        host K of each pruned to the sensor window, counted as whole, as FISTA's are)."""
        return 4 * self.n_bands

    def set_penalties(self, penalties: Penalties):
        """The penalties, and what depends on them (:meth:`CalibrationTerms.for_penalties`, kept as ``_penalty_terms``,
        whose gains a backend's steps take as they need them): μ₁conj(Ĥ), and the c-step's pivots
        (:meth:`_band_pivots`)."""
        self.penalties = penalties
        terms = self._penalty_terms = self.terms.for_penalties(penalties, self.axes)
        self._data_transfer = terms.data_transfer
        self._pivots = self._band_pivots(terms)

    def _band_pivots(self, terms: PenaltyTerms):
        """The c-step's pivots of ``terms``: the host's (:attr:`PenaltyTerms.pivots`)."""
        return terms.pivots

    @property
    def coupling(self) -> float:
        """e = μ₂,λ of the penalties the pivots are of (:func:`band_coupling`)."""
        return band_coupling(self.penalties, self.axes)

    def threshold(self, axis: int) -> float:
        """The u-step's soft threshold τw_d/μ₂,d along ``axis``."""
        return self.tv.weight * self.tv.axis_weights[axis] / self.penalties.tv_along(axis)

    def nonneg_shift(self) -> float:
        """The w-step's shift τ₁/μ₃ (0 without the L1 prior)."""
        return self.l1.weight / self.penalties.nonneg if self.l1 is not None else 0.0

    def iterate(self, state) -> tuple[float, tuple[float, float]]:
        """The c-step then the relaxed splits: (½‖b − SFHv‖² at the new v, (‖w⁺ − w‖², ‖w⁺‖²))."""
        self.c_step(state)
        return self.splits(state, self.relaxation)




def calibration_terms(problem) -> CalibrationTerms:
    """The :class:`CalibrationTerms` of ``problem``'s model, from the solver's shared store (built there on first
    use, so a video's frames share them)."""
    shared = problem.shared
    if TERMS_KEY not in shared:
        shared[TERMS_KEY] = CalibrationTerms(problem.model, problem.filters)
    return shared[TERMS_KEY]
