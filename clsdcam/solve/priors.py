"""Priors: each term of the regulariser is an object with its prox and its value; one table lists them.

The regulariser is g(v) = Σ_i τ_i·φ_i(v) + ι_{v≥0}(v). FISTA needs prox_{s·g}; as in the paper's solver,
the proxes of the active terms are averaged (the proximal average, as SCICO's ``ProxAvg``; exact for one
term), and non-negativity is then imposed by projection, so the cube is never negative:

    prox(z) = max(0, mean_i prox_{s·τ_i φ_i}(z))          (no active term: max(z, 0))

Weights. A user's weight is relative; each prior says what 1.0 means (its ``reference``, computed by
the solver for the measurement divided by max|b|): ``atb_max`` = ‖Aᵀb‖_∞ (the weight above which an L1
prior would zero the cube: TV, L1), ``atb_sigma1`` = σ₁(Aᵀb) (the largest singular value of the
pixels×bands unfolding of Aᵀb: nuclear norm), ``lipschitz`` = L = λmax(AᵀA) (quadratic priors: the data
term's stiffest curvature). So scaling a measurement by s scales the cube by s, and the same weights
suit any PSF or filter normalisation.

A weight can also be ``auto`` for a prior with an ``auto_weight`` rule: it starts at a relative weight
and, once the measurement's noise level σ̂ (relative to max|b|) is known (:mod:`clsdcam.solve.noise`), becomes
``per_noise``·σ̂. A soft-thresholding denoiser's best threshold grows with the noise (the universal
threshold is ∝ σ); ``per_noise`` is calibrated on the simulator's scenes (docs/benchmarks.md, "Choosing
``--tv``"). On a point-like scene (the algorithm's iterate at that point has its light in a few pixels,
:mod:`clsdcam.solve.auto_weights`) it is ``per_noise``·σ̂·min(1, σ̂/``point_noise``); on a widely lit scene (the
iterate's light spread over the frame) ``per_noise``·σ̂·max(1, σ̂²/(q·``lit_variance``)), q the measurement's mean
over its peak.

Adding a prior: one class (``prox``, ``value``, ``reference``; the math in its docstring) and one row
of :data:`PRIORS` (the ``Settings`` field and the ``--flag`` are generated from the row), and one test.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, ClassVar, NamedTuple

import numpy as np

AUTO = "auto"


class AutoWeight(NamedTuple):
    """A prior's rule for ``auto``: the relative weight before the noise is known, and per unit of noise."""

    start: float
    per_noise: float
    lowest: float
    highest: float
    point_noise: float | None = None    # σ0: on a point-like scene, the weight falls as σ̂² below it (None: it does not)
    # V1: on a widely lit scene, the weight rises as σ̂²/q above it, q the measurement's mean over its peak (None: it
    # does not)
    lit_variance: float | None = None

    def for_noise(self, noise: float, point_like: bool = False, lit_mean: float | None = None) -> float:
        """per_noise·σ̂, times min(1, σ̂/σ0) on a point-like scene and, on a widely lit one whose measurement's mean
        over its peak is ``lit_mean`` = q (None: not widely lit), max(1, σ̂²/(q·V1)), kept within [lowest, highest]
        (a q ≤ 0, as a dark-subtracted frame may read, keeps the rule's weight; a q near 0 takes the ceiling).

        A scene whose light sits in a few pixels and bands (narrow lines, point sources) wants a lighter weight in
        good light than the rule's σ̂ gives, and the same in low light (docs/convergence.md, "A lighter weight for
        point-like scenes in good light"). One whose light spreads over the frame (the real cubes) wants about the
        same in good light and a heavier one in low light ("A heavier weight for widely lit scenes in low light"), read
        as σ̂²/q, the noise's variance per unit of the mean signal: within one light, σ̂ (of the peak) grows with q,
        as the shot noise does, where the weight these scenes want falls with it ("The widely lit weight read per
        unit of mean light")."""
        factor = 1.0
        if point_like and self.point_noise:
            factor = min(1.0, noise / self.point_noise)
        elif lit_mean is not None and lit_mean > 0 and self.lit_variance:
            factor = max(1.0, noise * noise / (lit_mean * self.lit_variance))
        return float(np.clip(self.per_noise * noise * factor, self.lowest, self.highest))


class Prior:
    """One term τ·φ(v) with absolute weight τ > 0, on one backend."""

    name: ClassVar[str]
    reference: ClassVar[str]        # what a relative weight of 1 means (see the module docstring)
    auto_weight: ClassVar[AutoWeight | None] = None     # how ``auto`` chooses the weight (None: no auto)
    # subspace_prox(c, basis, step, out): out = Bᵀ·max(0, prox(B·c)) for coefficients c of basis B, fused;
    # None when the prior has none (the subspace then expands, applies prox_nonneg and projects); it runs on the
    # backend's optional fusion named ``fusion`` (a backend without it gets the unfused path)
    subspace_prox: ClassVar[Callable | None] = None
    fusion: ClassVar[str] = ""

    def __init__(self, backend, weight: float, settings):
        self.backend = backend
        self.weight = float(weight)
        self.unit = 1.0            # the absolute weight of a relative weight of 1 (set by build_priors)
        self.auto = False          # whether the weight is still to be chosen from the noise

    @property
    def relative(self) -> float:
        return self.weight / self.unit if self.unit else 0.0

    def set_relative(self, relative: float):
        self.weight = float(relative) * self.unit

    @property
    def active(self) -> bool:
        """Whether the term does anything (a zero weight removes it: it costs nothing)."""
        return self.weight > 0

    def prox(self, z, step: float, out):
        """out = prox_{step·τ·φ}(z) = argmin_x ½‖x − z‖² + step·τ·φ(x)."""
        raise NotImplementedError

    def value(self, x) -> float:
        """τ·φ(x)."""
        raise NotImplementedError

    def prox_nonneg(self, z, step: float, out):
        """out = max(0, prox_{step·τ·φ}(z)) (fused where the backend can)."""
        return self.backend.nonneg(self.prox(z, step, out), out=out)


class TotalVariation(Prior):
    """φ(v) = TV_w(v) = Σ_d w_d ‖∇_d v‖₁, the weighted anisotropic 3-D TV (axes λ, y, x; ``tv_weights`` are
    given as x, y, λ). Its prox is one parallel-proximal Haar step (Kamilov 2016, ``Backend.haar_tv``)."""

    name = "tv"
    reference = "atb_max"
    # V1 4e-4, fitted on 17 low-light widely lit scenes, checked on 21 more and judged on fresh seeds
    # (docs/convergence.md, "The widely lit weight read per unit of mean light")
    auto_weight = AutoWeight(start=3e-4, per_noise=0.06, lowest=3e-5, highest=3e-3, point_noise=0.009,
                             lit_variance=4e-4)
    fusion = "subspace_tv"

    def __init__(self, backend, weight: float, settings):
        super().__init__(backend, weight, settings)
        wx, wy, wl = settings.tv_weights
        self.axis_weights = (wl, wy, wx)

    @property
    def active(self) -> bool:
        return self.weight > 0 and any(w > 0 for w in self.axis_weights)

    def prox(self, z, step: float, out):
        return self.backend.haar_tv(z, step * self.weight, self.axis_weights, out=out)

    def prox_nonneg(self, z, step: float, out):
        return self.backend.haar_tv(z, step * self.weight, self.axis_weights, out=out, nonneg=True)

    def value(self, x) -> float:
        return self.weight * self.backend.tv_norm(x, self.axis_weights)

    def subspace_prox(self, c, basis, step: float, out):
        return self.backend.subspace_tv(c, basis, step * self.weight, self.axis_weights, out=out)


class LowRank(Prior):
    """φ(v) = ‖V‖_*, the nuclear norm of the pixels×bands unfolding V; its prox is singular-value
    thresholding through the K×K Gram matrix (:func:`lowrank_matrix`)."""

    name = "lowrank"
    reference = "atb_sigma1"

    def prox(self, z, step: float, out):
        return prox_lowrank(self.backend, z, step * self.weight, out=out)

    def value(self, x) -> float:
        return self.weight * float(np.sum(singular_values(self.backend, x)))


class Sparsity(Prior):
    """φ(v) = ‖v‖₁; its prox is soft thresholding."""

    name = "l1"
    reference = "atb_max"

    def prox(self, z, step: float, out):
        return self.backend.soft(z, step * self.weight, out=out)

    def value(self, x) -> float:
        return self.weight * self.backend.l1_norm(x)


class SpectralSmoothness(Prior):
    """φ(v) = ½ Σ_pixels ‖D v_p‖², D the second differences along λ ((Dv)_k = v_{k−1} − 2v_k + v_{k+1},
    per band index): smooth spectra, as the Spectral DiffuserScope's solver assumes. Quadratic, so its
    prox is linear and the same for every pixel: prox_{s·τφ}(z) = (I + sτ·DᵀD)⁻¹ z along the band axis,
    one ``bandmix`` with a K×K matrix; its value ½ Σ_p v_pᵀ DᵀD v_p = ½ tr(DᵀD·G), G the Gram matrix."""

    name = "spectral"
    reference = "lipschitz"

    def prox(self, z, step: float, out):
        return self.backend.bandmix(z, _smoothing_matrix(z.shape[0], step * self.weight), out=out)

    def value(self, x) -> float:
        return 0.5 * self.weight * float(np.sum(second_difference_gram(x.shape[0]) * self.backend.gram(x)))


def second_difference_gram(n_bands: int) -> np.ndarray:
    """DᵀD for the (K−2)×K second-difference matrix D (zero for K < 3)."""
    d = np.zeros((max(n_bands - 2, 0), n_bands))
    for k in range(n_bands - 2):
        d[k, k:k + 3] = (1.0, -2.0, 1.0)
    return d.T @ d


@lru_cache(maxsize=8)
def _smoothing_matrix(n_bands: int, strength: float) -> np.ndarray:
    """(I + strength·DᵀD)⁻¹ (the steps in use recur: cached)."""
    return np.linalg.inv(np.eye(n_bands) + strength * second_difference_gram(n_bands))


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


# ---- the table -----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PriorRow:
    """One prior as users meet it: the ``Settings`` field and ``--flag`` ``name``, default and help."""

    prior: type[Prior]
    default: float | str          # a relative weight, or AUTO for priors with an auto_weight rule
    help: str

    @property
    def name(self) -> str:
        return self.prior.name

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")


PRIORS: tuple[PriorRow, ...] = (
    PriorRow(TotalVariation, AUTO, "3-D total variation weight, relative to ‖Aᵀb‖∞ (axes weighted by --tv-weights), "
                                   "or auto: from the measurement's noise level"),
    PriorRow(LowRank, 0.0, "nuclear-norm (low-rank) weight, relative to σ₁(Aᵀb) (0: off)"),
    PriorRow(Sparsity, 0.0, "L1 (sparsity) weight, relative to ‖Aᵀb‖∞ (0: off)"),
    PriorRow(SpectralSmoothness, 0.0,
             "spectral smoothness weight (squared second differences along λ), relative to the Lipschitz constant (0: off)"),
)


def build_priors(backend, settings, references: Callable[[str], float]) -> list[Prior]:
    """The active priors of ``settings``: each row's relative weight (an ``auto`` one's start) times
    ``references(prior.reference)`` (called only for the references an active weight needs)."""
    priors = []
    for row in PRIORS:
        value = getattr(settings, row.name)
        relative = row.prior.auto_weight.start if value == AUTO else value
        if relative > 0:
            unit = references(row.prior.reference)
            prior = row.prior(backend, relative * unit, settings)
            prior.unit, prior.auto = unit, value == AUTO
            if prior.active:
                priors.append(prior)
    return priors


class ProxAverage:
    """prox of Σ_i τ_i φ_i + ι_{≥0} as max(0, mean_i prox_i(z)), and the value Σ_i τ_i φ_i, for cubes of
    ``shape`` on one backend (scratch allocated once)."""

    def __init__(self, backend, priors: list[Prior], shape):
        self.backend = backend
        self.priors = list(priors)
        self._scratch = backend.empty(shape) if len(self.priors) > 1 else None

    @property
    def names(self) -> list[str]:
        return [p.name for p in self.priors]

    def prox(self, z, step: float, out):
        """out = max(0, mean_i prox_{step·τ_i φ_i}(z))."""
        be = self.backend
        if not self.priors:
            return be.nonneg(z, out=out)
        if len(self.priors) == 1:
            return self.priors[0].prox_nonneg(z, step, out)
        self.priors[0].prox(z, step, out)
        for prior in self.priors[1:]:
            be.axpy(1.0, prior.prox(z, step, self._scratch), out, out=out)
        be.scale(1.0 / len(self.priors), out, out=out)
        return be.nonneg(out, out=out)

    def value(self, x) -> float:
        """Σ_i τ_i φ_i(x) (x ≥ 0 assumed: the indicator is 0)."""
        return float(sum(prior.value(x) for prior in self.priors))

    def fused_subspace(self) -> Callable | None:
        """The one prior's fused subspace prox ``(c, basis, step, out)``, or None (several priors or none, or a
        backend without the fusion it runs on)."""
        prior = self.priors[0] if len(self.priors) == 1 else None
        if prior is None or prior.subspace_prox is None or (prior.fusion and not hasattr(self.backend, prior.fusion)):
            return None
        return prior.subspace_prox
