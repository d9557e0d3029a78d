"""FISTA (Beck & Teboulle 2009) for min_x F(x) = f(x) + g(x), written once for every backend.

The loop knows nothing of the camera: it takes a gradient step, a prox, the objective and a
few vector operations of the backend. With step s (= 1/L):

    z   = y − s·∇f(y)                       (gradient_step)
    x⁺  = prox_{s·g}(z)                     (prox)
    t⁺  = (1 + √(1 + 4t²)) / 2
    y⁺  = x⁺ + ((t − 1)/t⁺)·(x⁺ − x)         (extrapolate)

Three safeguards, each recorded in the history:

* adaptive restart (O'Donoghue & Candès 2015, gradient scheme): when ⟨y − x⁺, x⁺ − x⟩ > 0
  the momentum points uphill, so t ← 1 (y⁺ = x⁺);
* monotone checkpoints (as MFISTA): every ``objective_every`` iterations F(x) is evaluated;
  the best iterate is kept, and a rise (beyond round-off, 64·eps·|F|) sends the iterates
  back to it with t ← 1, so the recorded objective never increases;
* step back-off: a non-finite value, a data term f(y) above 10³·F(best), or a checkpoint right
  after a rollback that does not lower F beyond round-off halves the step before going back
  to the best iterate. From the best point with t = 1, a step ≤ 1/L lowers F; when it does not,
  the step is too long for where the solve is (with the averaged TV prox, FISTA stalls at a
  level set by its step, and float32 and float64 would otherwise part there: one sees a rise
  where the other sees round-off).

It stops after ``iters`` iterations, when the relative change ‖x⁺ − x‖/‖x⁺‖ falls below
``tol`` ("tolerance"), when the objective fell by less than ``plateau`` (relative) between two
checkpoints ("plateau"), when ``should_stop`` says so, on Ctrl-C ("interrupted", returning
the best iterate), or after too many back-offs ("diverged"), and says why.

The loop is an object (:class:`Fista`) so that a solver can run it in phases and move its
iterates to another space in between (:meth:`Fista.change_space`: the spectral subspace),
keeping the momentum t; :func:`fista` is one phase from x0.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

MAX_BACKOFFS = 40   # 2⁻⁴⁰: a step that still diverges after this is not a step-size problem
BLOWUP = 1e3       # f(y) above BLOWUP·F(best) is divergence, not momentum overshoot
ROUNDOFF = 64       # a "rise" smaller than ROUNDOFF·eps·|F| is round-off, not a rise


def next_momentum(t: float) -> float:
    """t⁺ = (1 + √(1 + 4t²)) / 2  (the authors' Python has 1 + √(1 + 4t²)/2, a bug)."""
    return (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0


@dataclass
class FistaResult:
    x: Any
    iterations: int
    stop_reason: str
    step: float
    history: list[dict] = field(default_factory=list)


@dataclass(frozen=True)
class Rules:
    """When to stop, how often to check the objective, whether to restart the momentum."""

    tol: float = 0.0
    plateau: float = 0.0
    objective_every: int = 10
    restart: bool = True


class Fista:
    """FISTA's iterates (x, x_prev, y, z), momentum and safeguards, run phase by phase.

    gradient_step(y, out, step) writes z = y − step·∇f(y) into out and returns f(y);
    prox(z, out, step) writes prox_{step·g}(z) into out; objective(x) returns F(x) (without
    it, no checkpoints, no plateau rule and no back-off on rises). on_iteration(record, x)
    may add fields to the record; should_stop() returns a reason to stop or None.
    """

    def __init__(self, backend, x0, *, step: float, rules: Rules = Rules(),
                 objective: Callable[[Any], float] | None = None):
        self.backend = backend
        self.rules = rules
        self.eps = ROUNDOFF * float(np.finfo(backend.dtype).eps)
        self.history: list[dict] = []
        self.t = 1.0
        self.backoffs = 0
        self._start = time.perf_counter()
        self._enter(x0, step, objective)

    def _enter(self, x0, step: float, objective, evaluate: bool = True, keep=()):
        """Start a space: iterates from x0 (copied), the best so far = x0 (with F(x0) when ``evaluate``);
        ``keep``: arrays the caller still reads, which the iterates must not be written into."""
        be = self.backend
        self.x, self.x_prev, self.y, self.z, self.best = (be.copy(x0, out=out) for out in self._reusable(x0, keep))
        self.objective = objective
        self.best_objective = objective(self.x) if objective and evaluate else math.inf
        self.last_checkpoint = self.best_objective
        self.step = step
        self.rolled_back = False

    def change_space(self, mapping: Callable[[Any], Any], step: float, objective=None, keep_momentum: bool = True,
                     evaluate: bool = True):
        """Move x, x_prev and y through ``mapping`` (e.g. onto a spectral basis); keep t unless told not to;
        ``evaluate=False``: F of the moved x is not computed (the first checkpoint sets the best)."""
        x, x_prev, y = (mapping(a) for a in (self.x, self.x_prev, self.y))
        t = self.t if keep_momentum else 1.0
        self._enter(x, step, objective, evaluate, keep=(x_prev, y))
        be = self.backend
        be.copy(x_prev, out=self.x_prev)
        be.copy(y, out=self.y)
        self.t = t

    def change_objective(self, objective):
        """Go on from the same iterates, momentum and step under another objective (e.g. auto weights chosen):
        the best so far becomes x, scored by it."""
        self.objective = objective
        self.best_objective = self.last_checkpoint = objective(self.x)
        self.backend.copy(self.x, out=self.best)
        self.rolled_back = False

    def _reusable(self, x0, keep) -> list:
        """Where ``_enter`` copies x0 to: the previous space's five arrays when they have its shape and type and
        none is in ``keep`` (a space of the same size: no new cubes, whose first touch costs ~40 ms each for a
        64×256×320 cube on a 2-core VM), else new arrays (None)."""
        previous = [getattr(self, name, None) for name in ("x", "x_prev", "y", "z", "best")]
        same = all(a is not None and a.shape == x0.shape and a.dtype == x0.dtype for a in previous)
        if same and not any(a is b for a in previous for b in (x0, *keep)):
            return previous
        return [None] * len(previous)

    @property
    def iterations(self) -> int:
        return len(self.history)

    def run(self, gradient_step: Callable, prox: Callable, iters: int,
            on_iteration: Callable[[dict, Any], None] | None = None,
            should_stop: Callable[[], str | None] | None = None) -> str | None:
        """Up to ``iters`` more iterations; the reason it stopped early, or None."""
        try:
            for i in range(iters):
                k = self.iterations + 1
                record = self._iterate(gradient_step, prox)
                record["iteration"] = k
                if self.objective is not None and (k % self.rules.objective_every == 0 or k == 1 or i == iters - 1):
                    record.update(self._checkpoint(record))
                record["objective"] = record.get("objective", math.nan)
                record["seconds"] = time.perf_counter() - self._start
                self.history.append(record)        # counted before the callback: a Ctrl-C inside it keeps it
                if on_iteration is not None:
                    on_iteration(record, self.x)
                reason = self._stop_reason(record, should_stop)
                if reason:
                    return reason
        except KeyboardInterrupt:
            if self.objective is not None:
                self.backend.copy(self.best, out=self.x)
            return "interrupted"
        return None

    # ---- one iteration and its safeguards -------------------------------------------------
    def _iterate(self, gradient_step, prox) -> dict:
        """One FISTA step with the adaptive restart test; returns the record's numbers."""
        be = self.backend
        data = gradient_step(self.y, self.z, self.step)
        self.x, self.x_prev = self.x_prev, self.x
        prox(self.z, self.x, self.step)
        step_sq, norm_sq, slope = be.fista_stats(self.x, self.x_prev, self.y)   # ‖x⁺ − x‖², ‖x⁺‖², ⟨y − x⁺, x⁺ − x⟩
        change = _ratio(step_sq, norm_sq)
        uphill = self.rules.restart and slope > 0
        if uphill:
            self.t = 1.0
        t_next = next_momentum(self.t)
        be.extrapolate(self.x, self.x_prev, (self.t - 1.0) / t_next, out=self.y)  # y = x⁺ + β(x⁺ − x)
        self.t = t_next
        record = {"data": data, "change": change, "momentum": self.t, "restart": bool(uphill), "step": self.step,
                  "rollback": False, "backoff": False}
        if not (math.isfinite(data) and math.isfinite(change)) or data > BLOWUP * self.best_objective:
            record.update(self._back_off())
        return record

    def _checkpoint(self, record: dict) -> dict:
        """Keep x if F(x) is the best so far; otherwise go back to the best (and back off if needed)."""
        value = self.objective(self.x)
        allowed = -self.eps if self.rolled_back else self.eps    # after a rollback F must fall beyond round-off
        if math.isfinite(value) and value <= self.best_objective + allowed * abs(self.best_objective):
            self.best_objective, self.rolled_back = min(value, self.best_objective), False
            self.backend.copy(self.x, out=self.best)
            return {"objective": value}
        if self.rolled_back or not math.isfinite(value):
            return {**self._back_off(), "objective": self.best_objective}
        self.rolled_back = True
        self._go_to_best()
        return {"rollback": True, "objective": self.best_objective}

    def _back_off(self) -> dict:
        """Halve the step and restart from the best iterate."""
        self.step *= 0.5
        self.backoffs += 1
        self.rolled_back = False
        self._go_to_best()
        return {"backoff": True, "rollback": True, "step": self.step}

    def _go_to_best(self):
        for array in (self.x, self.x_prev, self.y):
            self.backend.copy(self.best, out=array)
        self.t = 1.0

    def _stop_reason(self, record: dict, should_stop) -> str | None:
        rules = self.rules
        if self.backoffs > MAX_BACKOFFS:
            return "diverged"
        if rules.tol > 0 and not record.get("rollback") and record["change"] < rules.tol:
            return "tolerance"
        if rules.plateau > 0 and math.isfinite(record["objective"]) and not record.get("rollback"):
            previous, self.last_checkpoint = self.last_checkpoint, record["objective"]
            if record["iteration"] > 1 and previous - record["objective"] < rules.plateau * abs(record["objective"]):
                return "plateau"
        return should_stop() if should_stop is not None else None


def fista(gradient_step: Callable, prox: Callable, backend, x0, *, step: float, iters: int, tol: float = 0.0,
          objective: Callable[[Any], float] | None = None, objective_every: int = 10, restart: bool = True,
          plateau: float = 0.0, on_iteration: Callable[[dict, Any], None] | None = None,
          should_stop: Callable[[], str | None] | None = None) -> FistaResult:
    """Run FISTA from x0 (a device array, not modified) in one phase; see :class:`Fista`."""
    loop = Fista(backend, x0, step=step, objective=objective,
                 rules=Rules(tol=tol, plateau=plateau, objective_every=objective_every, restart=restart))
    reason = loop.run(gradient_step, prox, iters, on_iteration, should_stop) or "iterations"
    return FistaResult(x=loop.x, iterations=loop.iterations, stop_reason=reason, step=loop.step, history=loop.history)


def _ratio(diff: float, norm: float) -> float:
    """√(diff/norm): 0 when both are zero."""
    if norm == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return math.sqrt(diff / norm) if math.isfinite(diff) and math.isfinite(norm) else math.inf
