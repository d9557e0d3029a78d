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
* step back-off: a non-finite value, a data term f(y) above 10³·F(best), or a rise right
  after such a restart (impossible for a step ≤ 1/L, since a proximal-gradient step from
  the best point then decreases F) halves the step before going back to the best iterate.

It stops after ``iters`` iterations, when the relative change ‖x⁺ − x‖/‖x⁺‖ falls below
``tol``, when ``should_stop`` says so, on Ctrl-C ("interrupted", returning the best
iterate), or after too many back-offs ("diverged"), and says why.
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


@dataclass
class _State:
    """The iterates and the safeguards' memory."""

    x: Any
    x_prev: Any
    y: Any
    z: Any
    best: Any
    best_objective: float
    step: float
    eps: float
    t: float = 1.0
    rolled_back: bool = False
    backoffs: int = 0


def fista(gradient_step: Callable, prox: Callable, backend, x0, *, step: float, iters: int, tol: float = 0.0,
          objective: Callable[[Any], float] | None = None, objective_every: int = 10, restart: bool = True,
          on_iteration: Callable[[dict, Any], None] | None = None,
          should_stop: Callable[[], str | None] | None = None) -> FistaResult:
    """Run FISTA from x0 (a device array, not modified).

    gradient_step(y, out, step) writes z = y − step·∇f(y) into out and returns f(y);
    prox(z, out, step) writes prox_{step·g}(z) into out; objective(x) returns F(x) (without
    it, no checkpoints and no back-off on rises). on_iteration(record, x) may add fields to
    the record. should_stop() returns a reason to stop or None.
    """
    be = backend
    s = _State(x=be.copy(x0), x_prev=be.copy(x0), y=be.copy(x0), z=be.copy(x0), best=be.copy(x0),
               best_objective=objective(x0) if objective else math.inf, step=step,
               eps=ROUNDOFF * float(np.finfo(be.dtype).eps))
    history: list[dict] = []
    start = time.perf_counter()
    reason = "iterations"
    try:
        for k in range(1, iters + 1):
            record = _iterate(be, gradient_step, prox, s, restart)
            record["iteration"] = k
            if objective is not None and (k % objective_every == 0 or k == 1 or k == iters):
                record.update(_checkpoint(be, objective, s, record))
            record["objective"] = record.get("objective", math.nan)
            record["seconds"] = time.perf_counter() - start
            if on_iteration is not None:
                on_iteration(record, s.x)
            history.append(record)
            stop = _stop_reason(record, s, tol, should_stop)
            if stop:
                reason = stop
                break
    except KeyboardInterrupt:
        reason = "interrupted"
        if objective is not None:
            be.copy(s.best, out=s.x)
    return FistaResult(x=s.x, iterations=len(history), stop_reason=reason, step=s.step, history=history)


def _iterate(be, gradient_step, prox, s: _State, restart: bool) -> dict:
    """One FISTA step with the adaptive restart test; returns the record's numbers."""
    data = gradient_step(s.y, s.z, s.step)
    s.x, s.x_prev = s.x_prev, s.x
    prox(s.z, s.x, s.step)
    step_sq, norm_sq, slope = be.fista_stats(s.x, s.x_prev, s.y)   # ‖x⁺ − x‖², ‖x⁺‖², ⟨y − x⁺, x⁺ − x⟩
    change = _ratio(step_sq, norm_sq)
    uphill = restart and slope > 0
    if uphill:
        s.t = 1.0
    t_next = next_momentum(s.t)
    be.extrapolate(s.x, s.x_prev, (s.t - 1.0) / t_next, out=s.y)  # y = x⁺ + β(x⁺ − x)
    s.t = t_next
    record = {"data": data, "change": change, "momentum": s.t, "restart": bool(uphill), "step": s.step,
              "rollback": False, "backoff": False}
    if not (math.isfinite(data) and math.isfinite(change)) or data > BLOWUP * s.best_objective:
        record.update(_back_off(be, s))
    return record


def _checkpoint(be, objective, s: _State, record: dict) -> dict:
    """Keep x if F(x) is the best so far; otherwise go back to the best (and back off if needed)."""
    value = objective(s.x)
    if math.isfinite(value) and value <= s.best_objective + s.eps * abs(s.best_objective):
        s.best_objective, s.rolled_back = min(value, s.best_objective), False
        be.copy(s.x, out=s.best)
        return {"objective": value}
    if s.rolled_back or not math.isfinite(value):
        return {**_back_off(be, s), "objective": s.best_objective}
    s.rolled_back = True
    _go_to_best(be, s)
    return {"rollback": True, "objective": s.best_objective}


def _back_off(be, s: _State) -> dict:
    """Halve the step and restart from the best iterate."""
    s.step *= 0.5
    s.backoffs += 1
    s.rolled_back = False
    _go_to_best(be, s)
    return {"backoff": True, "rollback": True, "step": s.step}


def _go_to_best(be, s: _State):
    for array in (s.x, s.x_prev, s.y):
        be.copy(s.best, out=array)
    s.t = 1.0


def _ratio(diff: float, norm: float) -> float:
    """√(diff/norm): 0 when both are zero."""
    if norm == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return math.sqrt(diff / norm) if math.isfinite(diff) and math.isfinite(norm) else math.inf


def _stop_reason(record: dict, s: _State, tol: float, should_stop) -> str | None:
    if s.backoffs > MAX_BACKOFFS:
        return "diverged"
    if tol > 0 and not record.get("rollback") and record["change"] < tol:
        return "tolerance"
    return should_stop() if should_stop is not None else None
