"""Where one solve starts (:class:`Start`) and what it leaves to the next frame of a stream on the same solver
(:class:`SolverState`, ``Result.state``).

A video's frames differ little: the next solve starts from the last field (the whole field, not only the sensor
window), enters the spectral basis the last one ended in at once, if it ended in one (``--subspace`` or ``--rank``:
no band-space warm-up, the rank kept), starts with the step it ended with (back-offs carried) and keeps the prior
weights it chose (an ``auto`` weight is not estimated again). Momentum starts afresh: the objective is a new one.
A cold start (zero, or a user's warm-start cube) is a :class:`Start` too, with no basis, weights or references.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


@dataclass
class SolverState:
    """The field (a backend array, in the calibration's units), the basis (K × r) or None for band space, the
    core rank, the step times the Lipschitz constant of its space, the priors' relative weights and their data
    references, and the fit ‖Av − b‖/‖b‖ the solve reached (what the next frame's solve may stop at:
    ``Solver.solve(stop_at_fit=…)``)."""

    field: Any
    basis: np.ndarray | None
    core: int
    step_factor: float
    weights: dict[str, float] = field(default_factory=dict)
    fit: float = 0.0
    references: dict[str, float] = field(default_factory=dict)

    def start(self, backend, units: float) -> "Start":
        """The next solve's start: this field times ``units`` (calibration units → the solver's), the rest kept."""
        return Start(backend.scale(units, self.field), self.step_factor, True, self.basis, self.core, self.weights,
                     self.references)


@dataclass(frozen=True)
class Start:
    """Where one solve begins: the first iterate (the solver's units, on the backend), the step times the
    Lipschitz constant of its space, whether it is warm (no warm-up before a subspace), a basis to enter at once
    (and its core rank), and prior weights and data references already chosen."""

    field: Any
    step_factor: float
    warm: bool
    basis: np.ndarray | None = None
    core: int = 0
    weights: dict[str, float] = field(default_factory=dict)
    references: dict[str, float] = field(default_factory=dict)

    def reference(self, fresh: Callable[[str], float]) -> Callable[[str], float]:
        """The weights' data references (e.g. ‖Aᵀb‖_∞ of b / max|b|) this start carries, for the priors (its
        weights stay what they were: no adjoint of a new b); ``fresh(name)`` for one it does not carry."""
        return lambda name: self.references[name] if name in self.references else fresh(name)

    def apply_weights(self, priors: list) -> None:
        """Give the priors the weights this start carries (auto ones included: no new estimate)."""
        for prior in priors:
            if prior.name in self.weights:
                prior.set_relative(self.weights[prior.name])
                prior.auto = False
