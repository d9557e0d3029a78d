"""Safeguards any algorithm runs under (:mod:`clsdcam.solve.driver`), each recorded in the history:

* monotone checkpoints (as MFISTA): every ``objective_every`` iterations F(x) is evaluated; the best iterate is
  kept, and a rise (beyond round-off, 64·eps·|F|) sends the algorithm back to it (``reset``: momentum afresh),
  so the recorded objective never increases (an algorithm whose ``monotone`` is False, as ADMM's, is never rolled
  back on a rise: its best iterate is kept all the same, for Ctrl-C);
* step back-off: a non-finite value, a data term f above 10³·F(best), or a checkpoint right after a rollback
  that does not lower F beyond round-off halves the step before going back to the best iterate. From the best
  point with the momentum reset, a proximal-gradient step ≤ 1/L lowers F; when it does not, the step is too long
  for where the solve is (with the averaged TV prox, FISTA stalls at a level set by its step, and float32 and
  float64 would otherwise part there: one sees a rise where the other sees round-off).

Without an objective there are no checkpoints and no back-off on rises.
"""
from __future__ import annotations

import math
from typing import Any, Callable

import numpy as np

from ..algorithms.base import place

MAX_BACKOFFS = 40   # 2⁻⁴⁰: a step that still diverges after this is not a step-size problem
BLOWUP = 1e3       # f(y) above BLOWUP·F(best) is divergence, not momentum overshoot
ROUNDOFF = 64       # a "rise" smaller than ROUNDOFF·eps·|F| is round-off, not a rise


class Checkpoints:
    """The best iterate and its objective for one algorithm; rollbacks and back-offs."""

    def __init__(self, algorithm, objective: Callable[[Any], float] | None, dtype):
        self.algorithm = algorithm
        self.backend = algorithm.backend
        self.eps = ROUNDOFF * float(np.finfo(dtype).eps)
        self.backoffs = 0
        self.best = None
        self.enter(objective)

    @property
    def active(self) -> bool:
        return self.objective is not None

    def enter(self, objective, evaluate: bool = True):
        """A new space or start: the best so far = the algorithm's x (scored by ``objective`` when ``evaluate``)."""
        x = self.algorithm.x
        (self.best,) = place(self.backend, [self.best], [x])
        self.objective = objective
        self.best_objective = objective(x) if objective and evaluate else math.inf
        self.last_checkpoint = self.best_objective
        self.rolled_back = False

    def rescore(self, objective):
        """Go on from the same iterates under another objective: the best so far becomes x, scored by it."""
        self.objective = objective
        self.best_objective = self.last_checkpoint = objective(self.algorithm.x)
        self.backend.copy(self.algorithm.x, out=self.best)
        self.rolled_back = False

    def guard(self, record: dict) -> dict:
        """After an iteration: back off on a non-finite or blown-up data term."""
        if not (math.isfinite(record["data"]) and math.isfinite(record["change"])) or \
                record["data"] > BLOWUP * self.best_objective:
            record.update(self.back_off())
        return record

    def check(self) -> dict:
        """Keep x if F(x) is the best so far; otherwise go back to the best (and back off if needed)."""
        value = self.objective(self.algorithm.x)
        allowed = -self.eps if self.rolled_back else self.eps    # after a rollback F must fall beyond round-off
        if math.isfinite(value) and value <= self.best_objective + allowed * abs(self.best_objective):
            self.best_objective, self.rolled_back = min(value, self.best_objective), False
            self.backend.copy(self.algorithm.x, out=self.best)
            return {"objective": value}
        if self.rolled_back or not math.isfinite(value):
            return {**self.back_off(), "objective": self.best_objective}
        if not self.algorithm.monotone:      # its F may rise on the way (ADMM): kept, not undone
            return {"objective": value}
        self.rolled_back = True
        self.algorithm.reset(self.best)
        return {"rollback": True, "objective": self.best_objective}

    def back_off(self) -> dict:
        """Halve the step and restart from the best iterate."""
        self.algorithm.step *= 0.5
        self.backoffs += 1
        self.rolled_back = False
        self.algorithm.reset(self.best)
        return {"backoff": True, "rollback": True, "step": self.algorithm.step}

    def fall_since_last(self, value: float) -> float:
        """How far F fell from the last checkpoint's value to ``value``, which becomes the last (the plateau rule)."""
        previous, self.last_checkpoint = self.last_checkpoint, value
        return previous - value

    def restore(self):
        """x ← the best iterate (an interrupted run returns it)."""
        if self.active:
            self.backend.copy(self.best, out=self.algorithm.x)

    @property
    def diverged(self) -> bool:
        return self.backoffs > MAX_BACKOFFS
