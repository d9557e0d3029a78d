"""The spaces one solve's iterates can live in, as the phases (:mod:`clsdcam.solve.phases`) see them: band space, the
spectral subspace of a basis (:mod:`clsdcam.solve.subspace`), the sensor window of an iterate, and the full-space step
the subspace's checks take. Built by the solver for each solve; nothing here reaches the solver."""
from __future__ import annotations

import hashlib
from functools import cached_property

import numpy as np

from ..camera.model import REFRESH_FLAT, REFRESH_TOL
from .priors import ProxAverage
from .problem import Problem
from .subspace import SpectralSubspace


class BandMixing:
    """The mapping c ↦ M·c along the band axis between two bases (``keeps_shape`` when M is square: an algorithm may
    then hand it ``out``, an array of the iterates' shape that is not c, and keep its cubes)."""

    def __init__(self, backend, matrix: np.ndarray):
        self.backend, self.matrix = backend, matrix
        self.keeps_shape = matrix.shape[0] == matrix.shape[1]

    def __call__(self, c, out=None):
        return self.backend.bandmix(c, self.matrix, out=out)


class LastLipschitz:
    """The Lipschitz constant of the last spectral basis a solver used (a stream's next frame carries its basis:
    no second power iteration for it)."""

    def __init__(self):
        self.key, self.value = None, None

    @staticmethod
    def digest(basis: np.ndarray) -> str:
        return hashlib.sha1(np.ascontiguousarray(basis, np.float64).tobytes()).hexdigest()

    def get(self, basis: np.ndarray) -> float | None:
        return self.value if self.key == self.digest(basis) else None

    def set(self, basis: np.ndarray, value: float):
        self.key, self.value = self.digest(basis), value


class Spaces:
    """Band space and the subspaces of one measurement b (normalised, on the device) under ``priors``."""

    def __init__(self, model, b, priors: list, filters: np.ndarray, lipschitz: float, last: LastLipschitz,
                 shared: dict | None = None):
        """``shared``: the solver's store across its solves, handed to every problem (none: one for this solve)."""
        self.model = model
        self.backend = model.backend
        self.b = b
        self.priors = priors
        self.filters = filters
        self.lipschitz = lipschitz           # band space's
        self.n_bands = model.n_bands
        self._last = last
        self._shared = {} if shared is None else shared
        self._buffers: dict = {}

    @cached_property
    def band(self) -> Problem:
        """The problem on the band cube (the full problem)."""
        average = ProxAverage(self.backend, self.priors, self.model.cube_shape)
        return Problem(self.model, self.b, average.prox, average.value, self.n_bands, **self._parts())

    def _parts(self) -> dict:
        """What every problem of this solve hands an algorithm's sub-problems
        (:class:`~clsdcam.solve.problem.Problem`)."""
        return {"priors": self.priors, "filters": self.filters, "shared": self._shared}

    def subspace(self, basis: np.ndarray, power: dict | None = None) -> Problem:
        """The problem on ``basis``: its L by a power iteration started as ``power`` says
        (:class:`~clsdcam.solve.subspace.SpectralSubspace`), else from band space's eigenvector projected onto the basis
        beside the flat cube; none when the last basis was the same."""
        known = self._last.get(basis)
        if power is None and known is None:
            power = {"start": self._unit(self.backend.bandmix(self.model.power_vector, basis.T))}
        sub = SpectralSubspace(self.model, basis, self.priors, self.filters, power, known, scratch=self._cube)
        self._last.set(basis, sub.lipschitz)
        return Problem(sub.model, self.b, sub.prox, sub.penalty, sub.rank, subspace=sub, **self._parts())

    def _unit(self, c):
        """c/‖c‖ (None when c is zero)."""
        norm = np.sqrt(self.backend.vdot(c, c))
        return self.backend.scale(1.0 / norm, c, out=c) if norm > 0 else None

    def onto(self, problem: Problem, basis: np.ndarray) -> tuple[Problem, object]:
        """The problem on another ``basis`` and the mapping of ``problem``'s coefficients to it, c ↦ B'ᵀB·c (lossless
        when span(B') ⊇ span(B)). A refresh (no wider than the old basis) starts its power iteration from the old
        eigenvector, mapped, with a faint flat part and a looser tolerance (REFRESH_FLAT, REFRESH_TOL: the old
        dominant direction stays near the new one), its first estimate compared with the old L; a wider basis,
        whose dominant direction may lie in its new columns, starts as a first subspace does."""
        subspace = problem.subspace
        mapping = BandMixing(self.backend, basis.T @ subspace.basis)
        vector = getattr(subspace.model, "power_vector", None)      # none when its L was known (no power iteration)
        start = None if vector is None else self._unit(mapping(vector))
        refresh = start is not None and basis.shape[1] <= subspace.rank
        power = {"start": start, "flat": REFRESH_FLAT, "tol": REFRESH_TOL, "expected": subspace.lipschitz}
        return self.subspace(basis, power if refresh else None), mapping

    def to_band(self, problem: Problem):
        """The mapping of ``problem``'s iterates to band space, v = B·c (a new array)."""
        return lambda c: self.backend.copy(problem.to_field(c))

    def window(self, x) -> np.ndarray:
        """The sensor window of a band cube, on the host."""
        return self.model.window(x)

    def full_step(self, problem: Problem, c, step: float, judged: bool = True) -> tuple:
        """One full proximal-gradient step from v = B·c, x⁺ = prox(v − step·Aᵀ(Av − b)): (the relative fall of the
        data term, the windows of v and of x⁺). Counts as A·B·c, then Aᵀr and A·x⁺. Not ``judged`` (a fixed rank,
        whose check reads only x⁺): (None, None, the window of x⁺), without A·x⁺ and the window of v."""
        full, sub = self.band, problem.subspace
        data = problem.data(c)                         # its residual A·B·c − b = A·v − b stays in place
        v = sub.expand(c)
        before = self.window(v) if judged else None
        z = self.model.adjoint(problem.residual_buffer, out=self._cube("z"), y=v, step=step)
        stepped = full.prox(z, step, self._cube("stepped"))
        gain = None
        if judged:
            gain = (data - full.data(stepped)) / data if data > 0 else 0.0
        return gain, before, self.window(stepped)

    def full_step_transforms(self, problem: Problem, judged: bool = True) -> int:
        band = self.band.transforms()
        return problem.transforms() // 2 + (band if judged else band // 2)

    def _cube(self, name: str):
        """A band cube for the checks and the subspaces' expansions (allocated at the first use of its name)."""
        if name not in self._buffers:
            self._buffers[name] = self.backend.empty(self.model.cube_shape)
        return self._buffers[name]
