"""A's filtered convolution, the operator each backend's ``convolution`` returns (``base.Convolution``).

With Ĥ the transfer function with the sensor window at the FFT origin
(:func:`clsdcam.camera.geometry.transfer_function`), F_k the filters and (H, W) the sensor:

    forward:   b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}
    adjoint:   (Aᵀr)_k = irfft2(conj(Ĥ) · rfft2(pad₀(F_k ⊙ r)))
    gradient step (fused):  z = y − s·Aᵀr

Two implementations of one operator, one per path (``base.py``):

* host path: :class:`HostPathConvolution` (:func:`host_path`), the band-chunked, pruned pocketfft pipeline
  (``host_convolution.py``) on the backend's host views (NumPy arrays as they are, an OpenCL CPU device's
  buffers mapped);
* device path: :class:`PrimitiveConvolution` (:func:`device_path`), whole cubes primitive by primitive
  (fft2 → cmul → ifft2 → mask_sum, and back), every step a kernel.

Both have ``forward``, ``adjoint``, ``with_filters`` (the same geometry and transfer with other filters:
the spectral subspace's G = BᵀF) and ``transforms``.
"""
from __future__ import annotations

from contextlib import ExitStack

from .host_convolution import HostConvolution

ORIGIN = (0, 0)


def host_path(backend, transfer, filters, field_shape, skip_unseen: bool = True) -> "HostPathConvolution":
    """The host path's convolution on ``backend``'s host views (``skip_unseen``: no FFTs for bands no filter sees)."""
    return HostPathConvolution(backend, HostConvolution(transfer, filters, field_shape, backend.dtype,
                                                        backend.workers, skip_unseen))


def device_path(backend, transfer, filters, field_shape, skip_unseen: bool = True) -> "PrimitiveConvolution":
    """The device path's convolution from ``backend``'s primitives (every band transformed: ``skip_unseen`` is the
    host pipeline's)."""
    return PrimitiveConvolution(backend, transfer, filters, field_shape)


class HostPathConvolution:
    """:class:`~clsdcam.backends.host_convolution.HostConvolution` on one backend's host views."""

    def __init__(self, backend, host: HostConvolution):
        self.backend = backend
        self.host = host
        self.n_bands = host.n_bands

    def forward(self, v, out):
        """b = Σ_k F_k ⊙ [irfft2(Ĥ · rfft2(v_k))]_{0:H, 0:W}."""
        view = self.backend.host_view
        with view(v, "r") as host_v, view(out, "w") as host_out:
            self.host.forward(host_v, host_out)
        return out

    def adjoint(self, r, out, y=None, step: float = 1.0):
        """out = Aᵀr, or the gradient step out = y − step·Aᵀr when y is given (out may be y itself)."""
        view = self.backend.host_view
        with ExitStack() as stack:
            host_r = stack.enter_context(view(r, "r"))
            if y is None:
                self.host.adjoint(host_r, stack.enter_context(view(out, "w")))
            elif out is y:
                host_y = stack.enter_context(view(y, "rw"))
                self.host.adjoint(host_r, host_y, host_y, step)
            else:
                host_y = stack.enter_context(view(y, "r"))
                self.host.adjoint(host_r, stack.enter_context(view(out, "w")), host_y, step)
        return out

    def with_filters(self, filters) -> "HostPathConvolution":
        return HostPathConvolution(self.backend, self.host.with_filters(filters))

    def transforms(self) -> int:
        return self.host.transforms()


class PrimitiveConvolution:
    """A's filtered convolution as fft2 → cmul → ifft2 → mask_sum (and back), on whole cubes of one backend."""

    def __init__(self, backend, transfer, filters, field_shape, transfer_on_device=None):
        be = self.backend = backend
        self.field_shape = tuple(field_shape)
        self.n_bands = filters.shape[0]
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
