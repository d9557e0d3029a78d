"""The spectral subspace: solve for r spectral basis vectors instead of K bands when the scene's spectra
span few dimensions.

With B (K × r, orthonormal columns) and v = B·c (c: r coefficient images on the field),

    A v = Σ_k F_k ⊙ crop(h ∗ Σ_j B_kj c_j) = Σ_j G_j ⊙ crop(h ∗ c_j),     G_j = Σ_k B_kj F_k,

so A·B is the same kind of operator with r "bands" of filters G: forward and adjoint need 4r
FFTs instead of 4K, and its Lipschitz constant ‖AB‖² ≤ ‖A‖² allows longer steps. The prox
stays in band space, c⁺ = Bᵀ·prox_g(B·c) (the priors and non-negativity act on the spectra; a
lone prior with a fused form, as TV's ``backend.subspace_tv``, runs fused), so the iterates are
exactly the full problem's restricted to span(B).

The basis comes from the spectra the solver has found so far, weighted as the spectral angle
weighs them: the unit spectra s_p = x_p/‖x_p‖ of the lit pixels of the sensor window (‖x_p‖ above
LIT of the brightest, as :func:`clsdcam.metrics.spectral_angle` counts them), so a faint object's
spectrum counts as much as a bright one's. With S their (K × N) matrix, the leading eigenvectors of
G = S Sᵀ/N span them best: 1 − Σ_{j≤r} λ_j is the mean sin² of the angle between a lit spectrum and
span(B) (:class:`Spectra`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .priors import ProxAverage


LIT = 0.05     # lit pixels: spectra brighter than this fraction of the brightest (as the spectral angle's)


def lit_pixels(window: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(spectra (K, P) float64, lit mask (P,), norms (P,)) of a host (K, H, W) window."""
    flat = np.asarray(window, np.float64).reshape(window.shape[0], -1)
    norms = np.linalg.norm(flat, axis=0)
    return flat, norms > LIT * norms.max() if norms.max() > 0 else norms > 0, norms


def lit_shapes(window: np.ndarray) -> np.ndarray:
    """(K, N) unit spectra s_p = x_p/‖x_p‖ of the lit pixels of a host (K, H, W) window."""
    flat, lit, norms = lit_pixels(window)
    return flat[:, lit] / norms[lit]


@dataclass(frozen=True)
class Spectra:
    """Eigenvalues (descending, ≥ 0) and eigenvectors (K × K) of the Gram matrix of a set of spectra."""

    energies: np.ndarray
    vectors: np.ndarray

    @classmethod
    def of(cls, backend, x) -> "Spectra":
        """Of every pixel of a device cube, weighted by its energy."""
        return cls.from_gram(backend.gram(x))

    @classmethod
    def of_shapes(cls, shapes: np.ndarray) -> "Spectra":
        """Of unit spectra (K, N), each counted once: energies are the mean squared cosines per direction."""
        return cls.from_gram(shapes @ shapes.T / max(shapes.shape[1], 1))

    @classmethod
    def from_gram(cls, gram: np.ndarray) -> "Spectra":
        values, vectors = np.linalg.eigh(gram)
        order = np.argsort(values)[::-1]
        return cls(np.clip(values[order], 0, None), vectors[:, order])

    def basis(self, rank: int) -> np.ndarray:
        return np.ascontiguousarray(self.vectors[:, :rank])

    def captured(self, rank: int) -> float:
        """Fraction of the energy in the first ``rank`` directions."""
        total = float(self.energies.sum())
        return float(self.energies[:rank].sum()) / total if total > 0 else 1.0

    def rank_for(self, tail: float) -> int:
        """The fewest directions leaving at most ``tail`` of the energy outside."""
        total = float(self.energies.sum())
        if total <= 0:
            return 1
        return int(np.searchsorted(np.cumsum(self.energies) / total, 1.0 - tail) + 1)


def turning_directions(basis: np.ndarray, before: np.ndarray, after: np.ndarray, most: int) -> np.ndarray:
    """Spectral directions outside span(B) that a full step from ``before`` to ``after`` (host (K, H, W) windows)
    turns the lit spectra towards more than it changes them inside: with d_p = (after_p − before_p)/‖after_p‖
    over the lit pixels of ``after``, the leading eigenvectors of Σ_p d⊥_p d⊥_pᵀ (d⊥ = d − BBᵀd) whose eigenvalue
    exceeds Σ_p ‖BBᵀd_p‖², at most ``most`` of them (K × m, possibly m = 0)."""
    flat_after, lit, norms = lit_pixels(after)
    change = (flat_after[:, lit] - np.asarray(before, np.float64).reshape(after.shape[0], -1)[:, lit]) / norms[lit]
    inside = basis @ (basis.T @ change)
    outside = Spectra.from_gram((change - inside) @ (change - inside).T)
    wanted = outside.energies[:most] > float(np.sum(inside ** 2))
    return outside.basis(most)[:, wanted]


def subspace_filters(basis: np.ndarray, filters: np.ndarray) -> np.ndarray:
    """G = BᵀF: G_j = Σ_k B_kj F_k (r, H, W) in float64, as one matrix product (BLAS, where an einsum without
    ``optimize`` loops in C without it)."""
    bands = filters.shape[0]
    return (basis.T @ filters.reshape(bands, -1)).reshape((basis.shape[1],) + filters.shape[1:])


class SpectralSubspace:
    """A, the prox and the objective for cubes v = B·c, on one backend; built once per basis."""

    def __init__(self, model, basis: np.ndarray, priors: list, filters: np.ndarray, power: dict | None = None,
                 lipschitz: float | None = None, scratch=None):
        """``power``: how the power iteration for L starts (``ForwardModel.lipschitz``'s ``start``, ``flat``, ``tol``,
        ``expected``);
        ``lipschitz``: L when already known for this basis (no power iteration; ``power_transforms``, the 2-D FFTs
        the power iteration took, is then 0); ``scratch(name)``: a band cube
        shared by every subspace of a solve (each expansion is read at once; a new 64-band cube faults in every page
        at its first touch), else one allocated here."""
        be = self.backend = model.backend
        self.basis = np.asarray(basis, dtype=np.float64)
        self.rank = self.basis.shape[1]
        self.full_model = model
        self.model = model.with_filters(subspace_filters(self.basis, filters).astype(be.dtype))
        if lipschitz:
            self.lipschitz, self.power_transforms = lipschitz, 0
        else:
            self.lipschitz = self.model.lipschitz(**(power or {}))
            self.power_transforms = self.model.power_passes * self.model.transforms()
        self.cube_shape = self.model.cube_shape
        scratch = scratch or (lambda name: be.empty(model.cube_shape))
        self._expanded = scratch("expanded")
        self._average = ProxAverage(be, priors, model.cube_shape)
        self._fused = self._average.fused_subspace()
        self._proxed = None if self._fused else scratch("proxed")

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
