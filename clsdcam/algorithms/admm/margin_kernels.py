"""The margin's correction on the kernels (``kernels/margin.cl``): :class:`~.margin.MarginCorrection`'s band terms on
the device and its four launches a c-step, so that the correction reads nothing back and the queue never waits for the
host. Worked out on the host, its band reads and writes stopped the queue twice an iteration: on an H200 an ADMM
iteration then cost 2.70–4.82× a FISTA one over a whole solve, and 1.91–3.68× with its first kernels
(docs/convergence.md, "Full size on a GPU, and the margin's correction on the device").

* ``admm_margin_split`` (before the solve along λ), from the band D of rfft2(x⁺ − ξ⁺) and the tracked band Q of the
  x-step's relaxed point: Ξ⁺ = (Q − D)/2 and x̂⁺ = D + Ξ⁺ (Ξ⁺ the band of ξ's spectrum, transformed on the device,
  where the band starts again);
* after it, three kernels: ``admm_margin_residual`` (Ĥv̂₀ − x̂⁺ in the modes along λ, the DCT-II as a K×K
  product), ``admm_margin_cg`` (``steps`` conjugate gradients from r₀ = μ₁Ĥ*(I − T)(Ĥv̂₀ − x̂⁺), one work group a mode
  with its plane in local memory: the system is block diagonal over the modes, each mode its own step lengths) and
  ``admm_margin_apply`` (δ̂ back in the bands with its column k_x = 0 made Hermitian, v̂ = v̂₀ + δ̂ and Ĥv̂ written
  into the two spectra's bands, and Q⁺ = αĤv̂ + (1 − α)x̂⁺ + Ξ⁺).

The band is small (at full size 64 × 15 × 10 coefficients). In one work group for the whole band, with one set of
step lengths, the correction took 2.6 ms of an H200's ADMM iteration (tools/bench_breakdown.py); a group a mode
spreads it over the device.
"""
from __future__ import annotations

import numpy as np
import scipy.fft

from ...backends.base import ints

LOCAL_PLANES = 7   # plane-sized arrays a mode's group works in, in local memory (r, z, p, A·p, δ̂, two temporaries)


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
        self.transfer, self.dct = up(correction.transfer, True), up(dct_matrix(n_bands))
        # admm_margin_cg's terms in its order: μ₁conj(Ĥ) on the band, P and P⁻¹ in the modes, T_y, T_x
        self.system = [up(correction.data_transfer, True), up(correction.diagonal), up(correction.inverse),
                       up(band.mask_y, True), up(band.mask_x, True)]
        self.split_band = backend.empty(self.shape, True)          # x̂⁺ on the band
        self.dual_band = backend.empty(self.shape, True)           # Ξ⁺ on the band
        self.residual = backend.empty(self.shape, True)            # Ĥv̂₀ − x̂⁺ in the modes
        self.delta = backend.empty(self.shape, True)               # δ̂ in the modes

    def split(self, state, data) -> None:
        """x̂⁺'s and Ξ⁺'s bands from ``data`` = rfft2(x⁺ − ξ⁺) and the tracked Q (``state.margin_band``); where Q is
        None, Ξ⁺ the band of ξ's spectrum (its window zero-padded, one transform of the field on the device)."""
        restart = state.margin_band is None
        if restart:
            be = self.backend
            tracked = be.fft2(be.pad(state.xi, self.correction.field_shape, (0, 0), out=state.v))  # v: free till ifft2
        else:
            tracked = state.margin_band
        self.kernels.grid1("admm_margin_split", self.size, data, tracked, self.split_band, self.dual_band,
                           np.int32(restart), *ints(self.size, *self.shape[1:], *data.shape[-2:]))

    def correct(self, state, data, rest) -> None:
        """v̂ ← v̂₀ + δ̂ in ``data``'s band, Ĥv̂ in ``rest``'s, and the next Q in ``state.margin_band`` (three
        launches: the residual, a work group a mode for the gradients, the correction applied)."""
        if state.margin_band is None:
            state.margin_band = self.backend.empty(self.shape, True)
        real, alpha, kernels = self.backend.dtype.type, self.correction.relaxation, self.kernels
        k, rows, cols = self.shape
        sizes = ints(rows, cols, *data.shape[-2:])
        kernels.grid1("admm_margin_residual", self.size, data, self.split_band, self.transfer, self.dct,
                      self.residual, np.int32(k), *sizes)
        plane_bytes = rows * cols * self.residual.dtype.itemsize
        kernels.row_groups("admm_margin_cg", k, rows * cols, self.residual, self.delta, self.transfer, *self.system,
                           *ints(self.correction.steps, rows, cols), local=(LOCAL_PLANES * plane_bytes,))
        kernels.grid1("admm_margin_apply", self.size, data, rest, self.split_band, self.dual_band, state.margin_band,
                      self.delta, self.transfer, self.dct, real(alpha), real(1 - alpha), np.int32(k), *sizes)
