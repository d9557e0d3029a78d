"""One measurement's problem in one space: the gradient step, prox and objective an algorithm uses
(:mod:`clsdcam.algorithms.base`).

    F(x) = ½‖A_s x − b‖² + g(E x)

where x is the band cube (E = I, A_s = A) or a spectral subspace's coefficients
(E = B, A_s = A·B, see :mod:`clsdcam.solve.subspace`). The phases move the iterates between spaces;
each space knows how to turn its iterate back into a band cube (:meth:`Problem.to_field`).
"""
from __future__ import annotations

from typing import Callable, Sequence


class Problem:
    """The data term through ``model`` and the prior through ``prox`` / ``penalty``, for one normalised b;
    ``subspace`` (a :class:`~clsdcam.solve.subspace.SpectralSubspace`) when x holds its coefficients. What an algorithm
    with sub-problems of its own builds them from (:mod:`clsdcam.algorithms.base`): ``priors`` (the priors g is made
    of), ``filters`` (the calibration's, (K, H, W)) and ``shared`` (the solver's store across its solves)."""

    def __init__(self, model, b, prox: Callable, penalty: Callable, rank: int, subspace=None, *,
                 priors: Sequence = (), filters=None, shared: dict | None = None):
        self.model = model
        self.backend = model.backend
        self.b = b
        self.prox = prox                 # prox(z, step, out): out = prox_{step·g}(z) in the space (g holds v ≥ 0)
        self.penalty = penalty
        self.rank = rank
        self.subspace = subspace
        self.priors = list(priors)
        self.filters = filters
        self.shared = {} if shared is None else shared
        self.residual_buffer = self.backend.empty(model.sensor_shape)

    def gradient_step(self, y, out, step: float) -> float:
        """out = y − step·A_sᵀ(A_s y − b) (fused in the adjoint); returns f(y) = ½‖A_s y − b‖²."""
        self.residual(y)
        data = 0.5 * self.backend.vdot(self.residual_buffer, self.residual_buffer)
        self.model.adjoint(self.residual_buffer, out=out, y=y, step=step)
        return data

    def residual(self, x):
        """r = A_s x − b (in the problem's buffer)."""
        self.model.forward(x, out=self.residual_buffer)
        return self.backend.axpy(-1.0, self.b, self.residual_buffer, out=self.residual_buffer)

    def data(self, x) -> float:
        self.residual(x)
        return 0.5 * self.backend.vdot(self.residual_buffer, self.residual_buffer)

    def objective(self, x) -> float:
        """F(x) = ½‖A_s x − b‖² + g(E x)."""
        return self.data(x) + self.penalty(x)

    def to_field(self, x):
        """The band cube E·x (x itself in band space)."""
        return x if self.subspace is None else self.subspace.expand(x)

    def solution(self, x):
        """The band cube of iterate x as a solution: E·x, projected onto v ≥ 0 (B·c can dip below 0 where
        the prox's max(0, ·) was followed by the projection onto the basis)."""
        if self.subspace is None:
            return x
        cube = self.subspace.expand(x)
        return self.backend.nonneg(cube, out=cube)

    def transforms(self) -> int:
        """2-D FFTs per gradient step."""
        return self.model.transforms()
