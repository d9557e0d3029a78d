"""The spectral subspace: solve for r spectral basis vectors instead of K bands when the scene's spectra
span few dimensions.

With B (K × r, orthonormal columns) and v = B·c (c: r coefficient images on the field),

    A v = Σ_k F_k ⊙ crop(h ∗ Σ_j B_kj c_j) = Σ_j G_j ⊙ crop(h ∗ c_j),     G_j = Σ_k B_kj F_k,

so A·B is the same kind of operator with r "bands" of filters G: forward and adjoint need 4r
FFTs instead of 4K, and its Lipschitz constant ‖AB‖² ≤ ‖A‖² allows longer steps. The prox
stays in band space, c⁺ = Bᵀ·prox_g(B·c) (the priors and non-negativity act on the spectra; a
lone prior with a fused form, as TV's ``backend.subspace_tv``, runs fused), so the iterates are
exactly the full problem's restricted to span(B).

The basis comes from the spectra the solver has found so far: the leading eigenvectors of
the K × K Gram matrix of its iterate (the pixels × bands unfolding's right singular vectors).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .priors import ProxAverage


@dataclass(frozen=True)
class Spectra:
    """The iterate's spectral decomposition: Gram eigenvalues (descending, ≥ 0) and eigenvectors (K × K)."""

    energies: np.ndarray
    vectors: np.ndarray

    @classmethod
    def of(cls, backend, x) -> "Spectra":
        values, vectors = np.linalg.eigh(backend.gram(x))
        order = np.argsort(values)[::-1]
        return cls(np.clip(values[order], 0, None), vectors[:, order])

    def basis(self, rank: int) -> np.ndarray:
        return np.ascontiguousarray(self.vectors[:, :rank])

    def captured(self, rank: int) -> float:
        """Fraction of the iterate's energy in its first ``rank`` directions."""
        total = float(self.energies.sum())
        return float(self.energies[:rank].sum()) / total if total > 0 else 1.0


class SpectralSubspace:
    """A, the prox and the objective for cubes v = B·c, on one backend; built once per basis."""

    def __init__(self, model, basis: np.ndarray, priors: list, filters: np.ndarray, start=None):
        """``start``: a coefficient cube to begin the power iteration for L from (a related basis's)."""
        be = self.backend = model.backend
        self.basis = np.asarray(basis, dtype=np.float64)
        self.rank = self.basis.shape[1]
        self.full_model = model
        self.model = model.with_filters(np.einsum("kj,khw->jhw", self.basis, filters).astype(be.dtype))
        self.lipschitz = self.model.lipschitz(start=start)
        self.cube_shape = self.model.cube_shape
        self._expanded = be.empty(model.cube_shape)
        self._average = ProxAverage(be, priors, model.cube_shape)
        self._fused = self._average.fused_subspace()
        self._proxed = None if self._fused else be.empty(model.cube_shape)

    def project(self, v):
        """c = Bᵀv (a band-space cube onto the basis)."""
        return self.backend.bandmix(v, self.basis.T)

    def expand(self, c, out=None):
        """v = B·c."""
        return self.backend.bandmix(c, self.basis, out=out if out is not None else self._expanded)

    def prox(self, c, step: float, out):
        """c⁺ = Bᵀ·prox_{step·g}(B·c)."""
        if self._fused:
            return self._fused(c, self.basis, step, out)
        self._average.prox(self.expand(c), step, out=self._proxed)
        return self.backend.bandmix(self._proxed, self.basis.T, out=out)

    def penalty(self, c) -> float:
        """g(B·c)."""
        return self._average.value(self.expand(c))

    def transforms(self) -> int:
        return self.model.transforms()
