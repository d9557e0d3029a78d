"""The Spectral DiffuserCam forward operator A, its adjoint, and its Lipschitz constant.

    A v = Σ_k F_k ⊙ crop(h ∗ v_k)                 (K, Hp, Wp) field -> (H, W) sensor
    Aᵀ r = [ h ⋆ pad(F_k ⊙ r) ]_k                 (H, W) -> (K, Hp, Wp)

The scene field is the padded field around the sensor (default 2H × 2W, as in the
paper); the convolution is circular on the field, which equals the linear convolution
on the sensor window as long as the field is at least sensor + PSF support − 1 wide.
Geometry: the PSF's origin is its centre pixel (H//2, W//2); the sensor window sits in
the field at offset (Hp//2 − H//2, Wp//2 − W//2), so a delta PSF at the centre makes A
the identity from the window to the sensor.
Written once over the backend primitives; knows nothing of the device.
"""
from __future__ import annotations

import numpy as np

from .errors import InputError


def window_offset(sensor_shape, field_shape) -> tuple[int, int]:
    """Offset of the sensor window inside the field: (Hp//2 − H//2, Wp//2 − W//2)."""
    return tuple(f // 2 - s // 2 for s, f in zip(sensor_shape, field_shape))


def default_field_shape(sensor_shape) -> tuple[int, int]:
    """The paper's field: twice the sensor in each direction."""
    return tuple(2 * s for s in sensor_shape)


def psf_transfer(psf: np.ndarray, field_shape) -> np.ndarray:
    """Ĥ = rfft2(ifftshift(pad(psf))): the PSF centre pixel moved to the field origin (host, float64)."""
    offset = window_offset(psf.shape, field_shape)
    field = np.zeros(field_shape)
    field[offset[0]:offset[0] + psf.shape[0], offset[1]:offset[1] + psf.shape[1]] = psf
    return np.fft.rfft2(np.fft.ifftshift(field))


class ForwardModel:
    """A and Aᵀ for one calibration on one backend, with preallocated work buffers."""

    def __init__(self, backend, psf: np.ndarray, filters: np.ndarray, field_shape=None):
        if filters.shape[-2:] != psf.shape:
            raise InputError(f"filters {filters.shape[-2:]} and psf {psf.shape} differ in shape")
        self.backend = backend
        self.sensor_shape = tuple(psf.shape)
        self.field_shape = tuple(field_shape or default_field_shape(psf.shape))
        if any(f < s for s, f in zip(self.sensor_shape, self.field_shape)):
            raise InputError(f"field {self.field_shape} is smaller than the sensor {self.sensor_shape}")
        self.offset = window_offset(self.sensor_shape, self.field_shape)
        self.n_bands = filters.shape[0]
        self.cube_shape = (self.n_bands,) + self.field_shape
        self.transfer = backend.to_device(psf_transfer(psf, self.field_shape), complex_=True)
        self.filters = backend.to_device(filters)
        spectrum_shape = (self.n_bands, self.field_shape[0], self.field_shape[1] // 2 + 1)
        self._spectrum = backend.empty(spectrum_shape, complex_=True)
        self._field = backend.empty(self.cube_shape)

    def forward(self, v, out=None):
        """b = Σ_k F_k ⊙ crop(irfft2(Ĥ · rfft2(v_k)))."""
        be = self.backend
        be.fft2(v, out=self._spectrum)
        be.cmul(self._spectrum, self.transfer, out=self._spectrum)
        be.ifft2(self._spectrum, self.field_shape, out=self._field)
        return be.mask_sum(self.filters, self._field, self.offset, out=out)

    def adjoint(self, r, out=None):
        """Aᵀr = irfft2(conj(Ĥ) · rfft2(pad(F_k ⊙ r)))."""
        be = self.backend
        be.mask_spread(self.filters, r, self.field_shape, self.offset, out=self._field)
        be.fft2(self._field, out=self._spectrum)
        be.cmul(self._spectrum, self.transfer, conj=True, out=self._spectrum)
        return be.ifft2(self._spectrum, self.field_shape, out=out)

    def embed(self, cube: np.ndarray):
        """A host (K, H, W) cube on the sensor window -> a device field cube, zero outside."""
        field = np.zeros(self.cube_shape, self.backend.dtype)
        oy, ox = self.offset
        field[:, oy:oy + self.sensor_shape[0], ox:ox + self.sensor_shape[1]] = cube
        return self.backend.to_device(field)

    def window(self, v) -> np.ndarray:
        """The sensor-sized window of a device field cube, on the host: (K, H, W)."""
        return self.backend.to_host(self.backend.crop(v, self.sensor_shape, self.offset))

    def lipschitz(self, iters: int = 12, margin: float = 1.02) -> float:
        """L ≈ margin · λmax(AᵀA) by power iteration from a flat start (the DC mode dominates).

        λ_j = ⟨v, AᵀAv⟩ / ⟨v, v⟩,  v ← AᵀAv / ‖AᵀAv‖; the Rayleigh quotient is a lower
        bound, hence the small safety margin.
        """
        be = self.backend
        v = be.to_device(np.full(self.cube_shape, 1.0 / np.sqrt(np.prod(self.cube_shape))))
        w = be.empty(self.cube_shape)
        b = be.empty(self.sensor_shape)
        eigenvalue = 0.0
        for _ in range(iters):
            self.adjoint(self.forward(v, out=b), out=w)
            eigenvalue = be.vdot(v, w) / be.vdot(v, v)
            norm = np.sqrt(be.vdot(w, w))
            if norm == 0.0:
                break
            be.scale(1.0 / norm, w, out=v)
        return margin * eigenvalue
