"""The filtered convolution at the heart of A, written once over the backend primitives.

With Ĥ the transfer function with the sensor window at the FFT origin
(:func:`clsdcam.geometry.transfer_function`), F_k the filters and (H, W) the sensor:

    forward:   b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}
    adjoint:   (Aᵀr)_k = irfft2(conj(Ĥ) · rfft2(pad₀(F_k ⊙ r)))
    gradient step (fused):  z = y − s·Aᵀr

Every convolution object has the same three methods and ``with_filters`` (the same geometry
and transfer with other filters: the spectral subspace's G = BᵀF). Backends pick the fastest
they have through ``backend.convolution(...)``: :class:`PrimitiveConvolution` here (whole
cubes, primitive by primitive: OpenCL on GPUs), or the host's band-chunked, pruned pocketfft
pipeline (:mod:`clsdcam.backends.host_convolution`: NumPy, and OpenCL on CPU devices).
"""
from __future__ import annotations

import numpy as np

ORIGIN = (0, 0)


def seen_bands(filters: np.ndarray) -> np.ndarray:
    """(K,) bool: bands whose filter is non-zero somewhere (the others add nothing to b and get no gradient)."""
    return np.any(np.asarray(filters) != 0, axis=tuple(range(1, np.ndim(filters))))


class PrimitiveConvolution:
    """A's filtered convolution as fft2 → cmul → ifft2 → mask_sum (and back), on whole cubes of one backend."""

    def __init__(self, backend, transfer, filters, field_shape, transfer_on_device=None):
        be = self.backend = backend
        self.field_shape = tuple(field_shape)
        self.sensor_shape = tuple(filters.shape[-2:])
        self.n_bands = filters.shape[0]
        self.seen = seen_bands(filters)
        self._transfer_host = transfer
        self.transfer = transfer_on_device if transfer_on_device is not None else be.to_device(transfer, complex_=True)
        self.filters = be.to_device(filters)
        self._spectrum = be.empty((self.n_bands, self.field_shape[0], self.field_shape[1] // 2 + 1), complex_=True)
        self._field = be.empty((self.n_bands,) + self.field_shape)

    def forward(self, v, out):
        """b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}."""
        be = self.backend
        be.fft2(v, out=self._spectrum)
        be.cmul(self._spectrum, self.transfer, out=self._spectrum)
        be.ifft2(self._spectrum, self.field_shape, out=self._field)
        return be.mask_sum(self.filters, self._field, ORIGIN, out=out)

    def adjoint(self, r, out, y=None, step: float = 1.0):
        """out = Aᵀr, or the gradient step out = y − step·Aᵀr when y is given (out may be y)."""
        be = self.backend
        be.mask_spread(self.filters, r, self.field_shape, ORIGIN, out=self._field)
        be.fft2(self._field, out=self._spectrum)
        be.cmul(self._spectrum, self.transfer, conj=True, out=self._spectrum)
        if y is None:
            return be.ifft2(self._spectrum, self.field_shape, out=out)
        be.ifft2(self._spectrum, self.field_shape, out=self._field)
        return be.axpy(-step, self._field, y, out=out)

    def with_filters(self, filters) -> "PrimitiveConvolution":
        return PrimitiveConvolution(self.backend, self._transfer_host, filters, self.field_shape, self.transfer)

    def transforms(self) -> int:
        """2-D transforms per forward + adjoint pair."""
        return 4 * self.n_bands
