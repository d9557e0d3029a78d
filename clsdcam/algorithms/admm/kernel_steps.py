"""ADMM's steps on a device with programs (the backend's optional :class:`~clsdcam.backends.base.Programs`, OpenCL's):
:class:`KernelSplitting`, the same iteration as :class:`~clsdcam.algorithms.admm.host_steps.Splitting` (derived in
:mod:`clsdcam.algorithms.admm`) on device arrays, on either path.

* the splits are three kernels of ``kernels/admm.cl``: the x-step (one work item per field pixel, which also sums
  the data term on the sensor window), the w-step (which also sums ‖w⁺ − w‖² and ‖w⁺‖²) and the u-step (every
  active TV axis in one pass);
* the c-step is the TV adjoint (one kernel), the backend's transforms (2K forward, 2K inverse), and between them
  one kernel that forms the right-hand side in Fourier, solves the tridiagonal system along λ at each Fourier
  coefficient by Thomas's sweeps and writes Ĥ·v̂ beside v̂ (admm_band_solve: v̂'s spectrum read and written twice,
  the other once); with the margin's correction (:mod:`.margin`), one kernel before it that takes the band of the
  data split's spectrum, and three after it that correct v̂'s and Ĥv̂'s bands (:mod:`.margin_kernels`).

Two scalar reads an iteration (the two reductions); the calibration's and the penalties' terms are uploaded once per
solver (``CalibrationTerms.on_device``), the margin's band terms (a few kilobytes) with each new set of penalties, and
the c-step's pivots formed on the device from the diagonal along λ (admm_band_pivots). The balance's RMS of the
iterate's differences is one more reduction (admm_difference_squares), w staying on the device.
"""
from __future__ import annotations

import math

import numpy as np

from ...backends.base import ints, total
from .margin import margin_correction
from .margin_kernels import KernelMarginCorrection
from .terms import CalibrationTerms, PenaltyTerms, SplitState, SplittingBase


class KernelSplitting(SplittingBase):
    """ADMM's steps for one band-space problem on a backend with programs (the module docstring); ``b`` the
    normalised measurement on the device."""

    def __init__(self, model, b, terms: CalibrationTerms, tv=None, l1=None, relaxation: float = 1.0,
                 margin_steps: int = 0):
        super().__init__(model, terms, tv, l1, relaxation, margin_steps)
        self.backend = model.backend
        self.workers = self.backend.workers         # MarginCorrection's (the host's arithmetic the kernels follow)
        self.kernels = self.backend.kernels
        self.b = b
        self.filters = terms.on_device(self.backend, "filters", terms.filters)
        self.transfer = terms.on_device(self.backend, "transfer", terms.transfer, complex_=True)
        self.mask = np.int32(sum(1 << axis for axis in self.axes))

    def set_penalties(self, penalties):
        """The penalties, the margin's correction of them (from the host terms), and their terms on the device: the
        x-step's reciprocal r (the gains f·r formed inline), μ₁conj(Ĥ), and the pivots formed there
        (:meth:`_band_pivots`)."""
        super().set_penalties(penalties)
        be, terms, margin = self.backend, self.terms, margin_correction(self)
        self.margin = margin and KernelMarginCorrection(margin, be, self.n_bands)
        self._reciprocal = terms.on_device(be, "reciprocal", self._penalty_terms.reciprocal)
        self._data_transfer = terms.on_device(be, "data transfer", self._data_transfer, complex_=True)

    def _band_pivots(self, terms: PenaltyTerms):
        """The c-step's pivots of ``terms``, formed on the device from its diagonal a and coupling e (one kernel,
        admm_band_pivots: the recursion of :func:`~.terms.band_pivots` at each Fourier coefficient, in float64 where
        the device has fp64), once for each set of penalties: the host's float64 recursion over the whole spectrum,
        and the upload of its result, are not made. A device without fp64 takes the host's pivots instead (a float32
        recursion loses the system's conditioning near singularity)."""
        if self._pivot_precision() != np.float64:
            return self.terms.on_device(self.backend, "pivots", super()._band_pivots(terms))
        return self.terms.made_on_device(self.backend, "pivots", terms, lambda: self._pivots_of(terms))

    def _pivot_precision(self) -> np.dtype:
        """admm_band_pivots' PIVOT: the accumulator where it is double, else the working precision."""
        return np.promote_types(self.kernels.acc, self.dtype)

    def _pivots_of(self, terms: PenaltyTerms):
        """admm_band_pivots' pivots (K, Hp, Wp//2 + 1) of ``terms``, a uploaded in float64."""
        be = self.backend
        diagonal = self.kernels.upload(terms.diagonal.astype(np.float64))
        pivots = be.empty((self.n_bands,) + diagonal.shape)
        self.kernels.grid1("admm_band_pivots", diagonal.size, pivots, diagonal, np.float64(terms.coupling),
                           np.int32(self.n_bands), np.int64(diagonal.size))
        return pivots

    # ---- the state -----------------------------------------------------------------------------------------
    def start(self, v0) -> tuple[SplitState, float]:
        """The state from v = v0 with zero duals: Hv by one convolution (2K transforms), then every split's step
        unrelaxed; and the data term at v0. The arrays a relaxed step reads (x, s) start at zero, others that every
        step writes before it reads them uninitialised."""
        be, cube = self.backend, self.shape
        spectrum = (self.n_bands, self.field_shape[0], self.field_shape[1] // 2 + 1)
        per_axis = (len(self.axes),) + cube
        state = SplitState(v=be.copy(v0), hv=be.empty(cube), x=be.zeros(cube),
                           xi=be.zeros((self.n_bands,) + self.sensor_shape),
                           rho=be.zeros(cube), w=be.zeros(cube), eta=be.zeros(per_axis), s=be.zeros(per_axis),
                           rest=be.empty(cube), spectra=(be.empty(spectrum, True), be.empty(spectrum, True)),
                           penalties=self.penalties)
        self._convolve(state.v, state.spectra[0], state.hv)
        data, _ = self.splits(state)
        return state, data

    # ---- one iteration -------------------------------------------------------------------------------------
    def c_step(self, state: SplitState) -> None:
        """v and Hv from the right-hand side the last splits left (x − ξ in ``hv``, the rest in ``rest``), with the
        margin's correction on their band before the inverse transforms."""
        be = self.backend
        self._add_tv_adjoint(state)
        data, rest = state.spectra
        be.fft2(state.hv, out=data)
        be.fft2(state.rest, out=rest)
        if self.margin:
            self.margin.split(state, data)
        self._band_solve(data, rest)
        if self.margin:
            self.margin.correct(state, data, rest)
        be.ifft2(data, self.field_shape, out=state.v)
        be.ifft2(rest, self.field_shape, out=state.hv)

    def splits(self, state: SplitState, alpha: float = 1.0) -> tuple[float, tuple[float, float]]:
        """The x-, w- and u-steps with their duals, relaxed by ``alpha``; the data term at v and (‖w⁺ − w‖², ‖w⁺‖²)."""
        k, (h, w), (bands, hp, wp) = self.kernels, self.sensor_shape, self.shape
        alpha = self._real(alpha)
        data = total(k.reduce("admm_x_step", hp * wp, state.hv, state.x, state.xi, self.filters, self._reciprocal,
                              self.b, *ints(bands, h, w, wp), alpha))
        step, norm = (total(row) for row in k.reduce("admm_w_step", state.v.size, state.v, state.rho, state.w,
                                                     state.rest, self._real(self.nonneg_shift()),
                                                     self._real(self.penalties.nonneg), alpha, outputs=2))
        if self.axes:
            k.grid3("admm_u_step", self.shape, state.eta, state.s, state.v, *ints(bands, hp, wp), self.mask,
                    *self._per_axis(self.threshold), alpha)
        return self.backend.drained(data), (step, norm)

    def _add_tv_adjoint(self, state: SplitState) -> None:
        """rest += Σ_d μ₂,d·D_dᵀs_d (one kernel)."""
        if self.axes:
            self.kernels.grid3("admm_tv_adjoint", self.shape, state.rest, state.s, *ints(*self.shape), self.mask,
                               *self._per_axis(self.penalties.tv_along))

    def rescale_tv_duals(self, state: SplitState, ratios: dict) -> None:
        """s_d ← s_d + (1 − r_d)η_d, η_d ← r_d·η_d for each active axis d, r_d = ``ratios[d]`` (one kernel)."""
        if self.axes:
            n = int(np.prod(self.shape))
            self.kernels.grid1("admm_rescale_tv_duals", n, state.eta, state.s, np.int64(n), self.mask,
                               *self._per_axis(ratios.get))

    def difference_rms(self, state: SplitState) -> dict[int, float]:
        """rms(D_d w) of the iterate for each active TV axis (:mod:`.balance`): Σ(D_d w)² summed on the device in
        one pass over w's rows (admm_difference_squares, the differences as the u-step takes them), three sums read
        back."""
        k, hp, _ = self.shape
        sums = self.kernels.reduce("admm_difference_squares", k * hp, state.w, *ints(*self.shape), self.mask,
                                   outputs=3)
        return self.backend.drained({axis: math.sqrt(total(sums[axis]) / state.w.size) for axis in self.axes})

    def _per_axis(self, value) -> list:
        """``value(axis)`` for each active axis, 0 for the others, in the backend's precision (a kernel's three
        arguments)."""
        return [self._real(value(axis) if axis in self.axes else 0.0) for axis in range(3)]

    def _band_solve(self, data, rest) -> None:
        """data ← v̂, the system along λ at each Fourier coefficient for the right-hand side μ₁conj(Ĥ)·data + rest,
        rest ← Ĥ·v̂ (one kernel)."""
        plane = data.shape[1] * data.shape[2]
        self.kernels.grid1("admm_band_solve", plane, data, rest, self._data_transfer, self.transfer, self._pivots,
                           self._real(self.coupling), np.int32(self.n_bands), np.int64(plane))

    def _convolve(self, v, spectrum, out):
        """Hv = irfft2(Ĥ·rfft2(v)) into ``out`` (2K transforms), ``spectrum`` its scratch."""
        be = self.backend
        be.fft2(v, out=spectrum)
        be.cmul(spectrum, self.transfer, out=spectrum)
        return be.ifft2(spectrum, self.field_shape, out=out)

    def _real(self, value):
        return self.dtype.type(value)
