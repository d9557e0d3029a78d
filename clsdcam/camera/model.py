"""The Spectral DiffuserCam forward operator A, its adjoint, and its Lipschitz constant.

    A v = Σ_k F_k ⊙ crop(h ∗ v_k)                 (K, Hp, Wp) field -> (H, W) sensor
    Aᵀ r = [ h ⋆ pad(F_k ⊙ r) ]_k                 (H, W) -> (K, Hp, Wp)

The scene field and the window in it are a :class:`~clsdcam.camera.geometry.FieldGeometry`: the
paper's 2H × 2W with the whole PSF frame by default, or the support-sized field of the
``--support-field`` option. The convolution is circular on the field, which equals the linear one on the
sensor window (see geometry.py). The filtered convolution is the backend's (``backend.convolution``,
:mod:`clsdcam.backends.convolution`: chunked host FFTs on the host path, whole-cube primitives on the device
path, one operator). Knows nothing of the device.
"""
from __future__ import annotations

from functools import cached_property

import numpy as np

from ..errors import InputError
from .geometry import FieldGeometry, centred_geometry, default_field_shape, transfer_function, window_offset

__all__ = ["ForwardModel", "default_field_shape", "window_offset"]

POWER_ITERS = 30          # at most, for the Lipschitz constant
POWER_TOL = 1e-4          # stop once the Rayleigh quotient moves less than this (relative)
REFRESH_FLAT = 0.01       # a refreshed basis's start: the flat cube's weight beside the old eigenvector, mapped
REFRESH_TOL = 1e-3        # and its tolerance, a tenth of the margin (clsdcam.solve.spaces.Spaces.onto)
PREDICTED_CHANGE = 4.0    # near the dominant vector, λ's next change over ‖AᵀAv‖/‖v‖ − λ, at most


class ForwardModel:
    """A and Aᵀ for one calibration on one backend (``geometry``: the paper's field unless given)."""

    def __init__(self, backend, psf: np.ndarray, filters: np.ndarray, field_shape=None,
                 geometry: FieldGeometry | None = None, convolution=None, skip_unseen: bool = True):
        if filters.shape[-2:] != psf.shape:
            raise InputError(f"filters {filters.shape[-2:]} and psf {psf.shape} differ in shape")
        self.backend = backend
        self.geometry = geometry or centred_geometry(psf.shape, field_shape)
        self.sensor_shape = self.geometry.sensor
        self.field_shape = self.geometry.field
        self.offset = self.geometry.offset
        self.n_bands = filters.shape[0]
        self.cube_shape = (self.n_bands,) + self.field_shape
        self.psf = psf
        self.convolution = convolution or backend.convolution(self.transfer, filters, self.field_shape,
                                                              skip_unseen=skip_unseen)

    @cached_property
    def transfer(self) -> np.ndarray:
        """Ĥ, the PSF's transfer function on the field (float64, on the host: :func:`transfer_function`), formed once
        for the model and what else needs it (ADMM's terms)."""
        return transfer_function(self.psf, self.geometry)

    def with_filters(self, filters: np.ndarray) -> "ForwardModel":
        """The same PSF and field with other filters (the spectral subspace's G_j = Σ_k B_kj F_k)."""
        return ForwardModel(self.backend, self.psf, filters, geometry=self.geometry,
                            convolution=self.convolution.with_filters(filters))

    def forward(self, v, out=None):
        """b = Σ_k F_k ⊙ crop(h ∗ v_k)."""
        out = self.backend.empty(self.sensor_shape) if out is None else out
        return self.convolution.forward(v, out)

    def adjoint(self, r, out=None, y=None, step: float = 1.0):
        """Aᵀr; or, given y, the gradient step y − step·Aᵀr (fused; out may be y)."""
        out = self.backend.empty(self.cube_shape) if out is None else out
        return self.convolution.adjoint(r, out, y, step)

    def transforms(self) -> int:
        """2-D FFTs one forward + adjoint pair costs."""
        return self.convolution.transforms()

    def embed(self, cube: np.ndarray):
        """A host (K, H, W) cube on the sensor window -> a device field cube, zero outside: the window uploaded and
        padded on the device (only the window's bytes cross to it)."""
        window = np.ascontiguousarray(np.broadcast_to(cube, (self.n_bands,) + self.sensor_shape), self.backend.dtype)
        return self.backend.pad(self.backend.to_device(window), self.field_shape, self.offset)

    def zero_field(self):
        """A device field cube of zeros (made there: nothing crosses)."""
        return self.backend.zeros(self.cube_shape)

    def window(self, v) -> np.ndarray:
        """The sensor-sized window of a device field cube, on the host: (K, H, W)."""
        return self.backend.to_host(self.window_on_device(v))

    def window_on_device(self, v):
        """The sensor-sized window of a device field cube, on the device: (K, H, W)."""
        return self.backend.crop(v, self.sensor_shape, self.offset)

    def lipschitz(self, margin: float = 1.01, iters: int = POWER_ITERS, tol: float = POWER_TOL, start=None,
                  flat: float = 1.0, expected: float | None = None) -> float:
        """L ≈ margin · λmax(AᵀA) by power iteration from ``flat`` times the unit flat cube (the DC mode dominates)
        plus ``start`` when given (a unit device cube near the dominant vector, e.g. a related model's: the flat
        part keeps every direction in play; a start known to be close, as a refreshed basis's, takes a faint one,
        REFRESH_FLAT). ``expected``: the L that start came with (the old basis's), the estimate the first pass is
        compared with: a refresh whose L has not moved stops after one pass.

        λ_j = ⟨v, AᵀAv⟩ / ⟨v, v⟩,  v ← AᵀAv / ‖AᵀAv‖, until λ moves less than ``tol`` (relative). From a
        ``start``, also as soon as the next pass is predicted to move it less: near the dominant vector, v = a·u₁ +
        b·u₂ with b small (eigenvalues λ₁ and λ₂ = λ₁ − g), ‖AᵀAv‖/‖v‖ − λ_j ≈ g²b²/(2λ) and λ_{j+1} − λ_j is
        2(1 + λ₂/λ₁) ≤ 4 times that (PREDICTED_CHANGE), so the iteration stops when 4(‖AᵀAv‖/‖v‖ − λ_j) ≤ tol·λ_j,
        one pass before the change is seen (a refresh whose start is already the new dominant vector stops after one
        pass, however far its L moved). From a start far from it the ratio can exceed 4, and the flat part is the
        guard, as it is for the first rule. The Rayleigh quotient is a lower bound, hence the small safety margin
        (the solver's step back-off catches the rest). The last v, one pass further than the λ read from it, is kept
        in ``power_vector`` (to start a related model's iteration from it), the number of AᵀA passes in
        ``power_passes``.
        """
        be = self.backend
        v = be.to_device(np.full(self.cube_shape, flat / np.sqrt(np.prod(self.cube_shape)), dtype=be.dtype))
        if start is not None:
            be.axpy(1.0, start, v, out=v)
        w = be.empty(self.cube_shape)
        b = be.empty(self.sensor_shape)
        eigenvalue = expected / margin if expected else 0.0
        self.power_passes = 0
        for _ in range(iters):
            self.adjoint(self.forward(v, out=b), out=w)
            self.power_passes += 1
            length_sq = be.vdot(v, v)
            previous, eigenvalue = eigenvalue, be.vdot(v, w) / length_sq
            norm = np.sqrt(be.vdot(w, w))
            if norm == 0.0:
                break
            be.scale(1.0 / norm, w, out=v)
            predicted = PREDICTED_CHANGE * (norm / np.sqrt(length_sq) - eigenvalue)     # λ_{j+1} − λ_j, at most
            settled = start is not None and predicted <= tol * eigenvalue
            if settled or abs(eigenvalue - previous) <= tol * eigenvalue:
                break
        self.power_vector = v
        return margin * eigenvalue
