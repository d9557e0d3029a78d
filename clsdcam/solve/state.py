"""Where one solve starts (:class:`Start`) and what it leaves to the next frame of a stream on the same solver
(:class:`SolverState`, ``Result.state``).

A video's frames differ little: the next solve starts from the last field (the whole field, not only the sensor
window), enters the spectral basis the last one ended in at once, if it ended in one (``--subspace`` or ``--rank``:
no band-space warm-up, the rank kept), starts with the step it ended with (back-offs carried) and keeps the prior
weights it chose (an ``auto`` weight is not estimated again). Momentum starts afresh: the objective is a new one.
An algorithm with more state than its iterate (ADMM's splits and duals) leaves it in ``carry`` and resumes from it
(``algorithm.resume``), scaled to the new measurement's units and handed over once (no copy of its arrays); a
field moved by the drift keeps only what its ``moved()`` keeps (ADMM's penalties: :func:`clsdcam.batch.motion.predict_state`). A cold start (zero, or a user's warm-start cube) is a :class:`Start`
too, with no basis, weights, references or carry.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np


@dataclass
class SolverState:
    """The field (a backend array, in the calibration's units), the basis (K × r) or None for band space, the
    core rank, the step times the Lipschitz constant of its space, the priors' relative weights and their data
    references, the fit ‖Av − b‖/‖b‖ the solve reached (what the next frame's solve may stop at:
    ``Solver.solve(stop_at_fit=…)``), and the algorithm's carry (see the module docstring)."""

    field: Any
    basis: np.ndarray | None
    core: int
    step_factor: float
    weights: dict[str, float] = field(default_factory=dict)
    fit: float = 0.0
    references: dict[str, float] = field(default_factory=dict)
    carry: tuple | None = None     # (what the algorithm can resume from, the factor to the calibration's units)

    def start(self, backend, units: float) -> "Start":
        """The next solve's start: this field times ``units`` (calibration units → the solver's), the rest kept. The
        carry is handed over, not copied (its arrays become the next solve's): a second start from this state has
        none, and its algorithm starts afresh from the field."""
        carry, self.carry = None if self.carry is None else (self.carry[0], self.carry[1] * units), None
        return Start(backend.scale(units, self.field), self.step_factor, True, self.basis, self.core, self.weights,
                     self.references, carry)


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
    carry: tuple | None = None     # (the algorithm's state to resume, the factor taking it to this solve's units)

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
