"""Priors and their proximal operators, written once over the backend primitives.

The regulariser is g(v) = τ₁·TV_w(v) + τ₂·‖V‖_* + τ₃·‖v‖₁ + ι_{v≥0}(v), where
TV_w(v) = Σ_d w_d ‖∇_d v‖₁ is the weighted anisotropic 3-D TV (axes λ, y, x) and V the
pixels×bands unfolding. FISTA needs prox_{g/L}. As in the paper's solver, the proxes of
the active terms are averaged (the proximal average, which is exact for one term); unlike
the paper, non-negativity is then imposed by projection so the cube is never negative:

    prox(z) = max(0, mean_i prox_{τ_i φ_i / L}(z))

with no active term, prox(z) = max(z, 0). Weights here are absolute (the solver scales the
user's relative weights by the data, see ``clsdcam.solver``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Regularizer:
    """Absolute weights of each term; a zero weight removes the term (it costs nothing)."""

    tv: float = 0.0
    tv_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)  # (x, y, λ), as on the command line
    lowrank: float = 0.0
    l1: float = 0.0

    @property
    def axis_weights(self) -> tuple[float, float, float]:
        """TV weights in cube axis order (λ, y, x)."""
        wx, wy, wl = self.tv_weights
        return (wl, wy, wx)

    def active_terms(self) -> list[str]:
        terms = []
        if self.tv > 0 and any(w > 0 for w in self.tv_weights):
            terms.append("tv")
        if self.lowrank > 0:
            terms.append("lowrank")
        if self.l1 > 0:
            terms.append("l1")
        return terms

    def inactive_terms(self) -> list[str]:
        """Terms with zero weight: never evaluated."""
        return [term for term in ("tv", "lowrank", "l1") if term not in self.active_terms()]

    def value(self, backend, v) -> float:
        """g(v) without the indicator (v is assumed non-negative)."""
        total = 0.0
        if "tv" in self.active_terms():
            total += self.tv * backend.tv_norm(v, self.axis_weights)
        if self.lowrank > 0:
            total += self.lowrank * float(np.sum(singular_values(backend, v)))
        if self.l1 > 0:
            total += self.l1 * backend.l1_norm(v)
        return total


def singular_values(backend, v) -> np.ndarray:
    """σ of the pixels×bands unfolding, from the eigenvalues of its K×K Gram matrix."""
    return np.sqrt(np.clip(np.linalg.eigvalsh(backend.gram(v)), 0, None))


def lowrank_matrix(gram: np.ndarray, threshold: float) -> np.ndarray:
    """M = V diag(max(σ − t, 0)/σ) Vᵀ so that V_out = M·V_in is singular-value thresholding.

    With X = U Σ Vᵀ (pixels×bands) and G = XᵀX = V Σ² Vᵀ:
    SVT(X) = U max(Σ − t, 0) Vᵀ = X · V diag(max(σ − t, 0)/σ) Vᵀ.
    """
    eigenvalues, vectors = np.linalg.eigh(gram)
    sigma = np.sqrt(np.clip(eigenvalues, 0, None))
    shrink = np.divide(np.maximum(sigma - threshold, 0), sigma, out=np.zeros_like(sigma), where=sigma > 0)
    return (vectors * shrink) @ vectors.T


def prox_lowrank(backend, z, threshold, out=None):
    """Singular-value thresholding of the pixels×bands unfolding, through the K×K Gram matrix."""
    return backend.bandmix(z, lowrank_matrix(backend.gram(z), threshold), out=out)


class Prox:
    """prox_{g/L} for one regulariser, with its scratch buffers allocated once."""

    def __init__(self, backend, regularizer: Regularizer, shape):
        self.backend = backend
        self.regularizer = regularizer
        self.terms = regularizer.active_terms()
        self._scratch = backend.empty(shape) if len(self.terms) > 1 else None

    def __call__(self, z, step: float, out):
        """out = max(0, mean_i prox_{step·τ_i φ_i}(z))."""
        be = self.backend
        if not self.terms:
            return be.nonneg(z, out=out)
        self._term(self.terms[0], z, step, out)
        for term in self.terms[1:]:
            be.axpy(1.0, self._term(term, z, step, self._scratch), out, out=out)
        if len(self.terms) > 1:
            be.scale(1.0 / len(self.terms), out, out=out)
        return be.nonneg(out, out=out)

    def _term(self, term: str, z, step: float, out):
        be, reg = self.backend, self.regularizer
        if term == "tv":
            return be.haar_tv(z, step * reg.tv, reg.axis_weights, out=out)
        if term == "lowrank":
            return prox_lowrank(be, z, step * reg.lowrank, out=out)
        return be.soft(z, step * reg.l1, out=out)
