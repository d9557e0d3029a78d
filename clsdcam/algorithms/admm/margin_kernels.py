"""The margin's correction on the kernels (``kernels/margin.cl``): :class:`~.margin.MarginCorrection`'s band terms on
the device and its two launches a c-step, so that the correction reads nothing back (but ξ, where its band starts
again) and the queue never waits for the host. Worked out on the host, its band reads and writes stopped the queue
twice an iteration: on an H200 an ADMM iteration then cost 2.70–4.82× a FISTA one over a whole solve, and 1.91–3.68×
with these kernels (docs/convergence.md, "Full size on a GPU, and the margin's correction on the device").

* ``admm_margin_split`` (before the solve along λ), from the band D of rfft2(x⁺ − ξ⁺) and the tracked band Q of the
  x-step's relaxed point: Ξ⁺ = (Q − D)/2 and x̂⁺ = D + Ξ⁺ (Ξ⁺ transformed from ξ on the host where the band starts
  again, :meth:`~.margin.MarginCorrection.dual_band`);
* ``admm_margin_correct`` (after it), in one work group: the residual r₀ = μ₁Ĥ*(I − T)(Ĥv̂₀ − x̂⁺), ``steps``
  conjugate gradients in the modes along λ (the DCT-II as a K×K product), δ̂ back in the bands with its column k_x = 0
  made Hermitian, v̂ = v̂₀ + δ̂ and Ĥv̂ written into the two spectra's bands, and Q⁺ = αĤv̂ + (1 − α)x̂⁺ + Ξ⁺.

The band is small (at full size 64 × 15 × 10 coefficients): one work group does a step's passes with barriers between
them and the inner products as group reductions, where several groups would need a launch each.
"""
from __future__ import annotations

import numpy as np
import scipy.fft

from ...backends.base import ints

SCRATCH = 7        # band-sized arrays the correction works in (two temporaries, r, z, p, A·p, δ̂)


def dct_matrix(n: int) -> np.ndarray:
    """The orthonormal DCT-II as an n×n matrix: (C·z)_j = the transform's coefficient j of z."""
    return scipy.fft.dct(np.eye(n), type=2, axis=0, norm="ortho")


class KernelMarginCorrection:
    """One :class:`~.margin.MarginCorrection` (``correction``: its penalties' terms, and the host's arithmetic the
    kernels follow) on ``backend``'s device."""

    def __init__(self, correction, backend, n_bands: int):
        self.correction, self.backend, self.kernels = correction, backend, backend.kernels
        band, up = correction.band, backend.to_device
        self.shape = (n_bands, len(band.rows), band.columns)
        self.size = int(np.prod(self.shape))
        # the terms in admm_margin_correct's order: Ĥ and μ₁conj(Ĥ) on the band, P and P⁻¹ in the modes, T_y, T_x, C
        self.terms = [up(correction.transfer, True), up(correction.data_transfer, True), up(correction.diagonal),
                      up(correction.inverse), up(band.mask_y, True), up(band.mask_x, True), up(dct_matrix(n_bands))]
        self.split_band = backend.empty(self.shape, True)          # x̂⁺ on the band
        self.dual_band = backend.empty(self.shape, True)           # Ξ⁺ on the band
        self.scratch = backend.empty((SCRATCH,) + self.shape, True)

    def split(self, state, data) -> None:
        """x̂⁺'s and Ξ⁺'s bands from ``data`` = rfft2(x⁺ − ξ⁺) and the tracked Q (``state.margin_band``); where Q is
        None, Ξ⁺ transformed from ξ on the host and uploaded."""
        restart = state.margin_band is None
        if restart:
            dual = self.correction.dual_band(self.backend.to_host(state.xi))
            self.dual_band.set(np.ascontiguousarray(dual, self.dual_band.dtype))
        tracked = self.dual_band if restart else state.margin_band
        self.kernels.grid1("admm_margin_split", self.size, data, tracked, self.split_band, self.dual_band,
                           np.int32(restart), *ints(self.size, *self.shape[1:], *data.shape[-2:]))

    def correct(self, state, data, rest) -> None:
        """v̂ ← v̂₀ + δ̂ in ``data``'s band, Ĥv̂ in ``rest``'s, and the next Q in ``state.margin_band`` (one work
        group)."""
        if state.margin_band is None:
            state.margin_band = self.backend.empty(self.shape, True)
        real, alpha = self.backend.dtype.type, self.correction.relaxation
        self.kernels.one_group("admm_margin_correct", self.size, data, rest, self.split_band, self.dual_band,
                               state.margin_band, *self.terms, self.scratch, real(alpha), real(1 - alpha),
                               np.int32(self.correction.steps), *ints(*self.shape, *data.shape[-2:]))
