"""What one solve leaves to the next frame of a stream on the same solver (``Result.state``).

A video's frames differ little: the next solve starts from the last field (the whole field, not only
the sensor window), enters the spectral basis the last one ended in at once, if it ended in one (``--subspace``
or ``--rank``: no band-space warm-up, the rank kept), starts with the step it ended with (back-offs carried) and keeps the prior weights it chose
(an ``auto`` weight is not estimated again). Momentum starts afresh: the objective is a new one.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

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

    def reference(self, fresh):
        """The weights' data references (e.g. ‖Aᵀb‖_∞ of b / max|b|) this state's solve used, for the priors of the
        next: its weights stay what they were (no adjoint of a new b); ``fresh(name)`` for one it did not use."""
        return lambda name: self.references[name] if name in self.references else fresh(name)

    def apply_weights(self, priors: list) -> None:
        """Give the priors the weights this state's solve used (auto ones included: no new estimate)."""
        for prior in priors:
            if prior.name in self.weights:
                prior.set_relative(self.weights[prior.name])
                prior.auto = False
