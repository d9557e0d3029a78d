"""FISTA (Beck & Teboulle 2009) for min_x f(x) + g(x), written once for every backend.

The loop knows nothing of the camera: it takes a gradient step, a prox and a few vector
operations of the backend:

    z   = y − ∇f(y)/L                      (gradient_step)
    x⁺  = prox_{g/L}(z)                    (prox)
    t⁺  = (1 + √(1 + 4t²)) / 2
    y⁺  = x⁺ + ((t − 1)/t⁺)·(x⁺ − x)        (extrapolate)

It stops after ``iters`` iterations, or when the relative change ‖x⁺ − x‖/‖x⁺‖ falls
below ``tol``, or when ``should_stop`` says so, and reports why.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable


def next_momentum(t: float) -> float:
    """t⁺ = (1 + √(1 + 4t²)) / 2  (the authors' Python has 1 + √(1 + 4t²)/2, a bug)."""
    return (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0


@dataclass
class FistaResult:
    x: Any
    iterations: int
    stop_reason: str
    history: list[dict] = field(default_factory=list)


def fista(gradient_step: Callable, prox: Callable, backend, x0, *, iters: int, tol: float = 0.0,
          on_iteration: Callable[[dict, Any], None] | None = None,
          should_stop: Callable[[], str | None] | None = None) -> FistaResult:
    """Run FISTA from x0 (a device array, not modified).

    gradient_step(y, out) writes z = y − ∇f(y)/L into out and returns f(y), with step 1/L;
    prox(z, out) writes prox_{g/L}(z) into out. on_iteration(record, x) may add fields
    to the record (e.g. the objective at x). should_stop() returns a reason to stop or None.
    """
    be = backend
    x, x_prev = be.copy(x0), be.copy(x0)
    y, z = be.copy(x0), be.copy(x0)
    t = 1.0
    history: list[dict] = []
    start = time.perf_counter()
    reason = "iterations"
    for k in range(1, iters + 1):
        data = gradient_step(y, z)
        x, x_prev = x_prev, x
        prox(z, x)
        change = relative_change(be, x, x_prev, scratch=z)
        t_next = next_momentum(t)
        be.extrapolate(x, x_prev, (t - 1.0) / t_next, out=y)  # y = x⁺ + β(x⁺ − x)
        t = t_next
        record = {"iteration": k, "data": data, "change": change, "momentum": t,
                  "seconds": time.perf_counter() - start}
        if on_iteration is not None:
            on_iteration(record, x)
        history.append(record)
        stop = _stop_reason(change, tol, should_stop)
        if stop:
            reason = stop
            break
    return FistaResult(x=x, iterations=len(history), stop_reason=reason, history=history)


def relative_change(be, x, x_prev, scratch) -> float:
    """‖x − x_prev‖ / ‖x‖ (0 when both are zero), using ``scratch`` for the difference."""
    be.axpy(-1.0, x_prev, x, out=scratch)
    norm = be.vdot(x, x)
    diff = be.vdot(scratch, scratch)
    if norm == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return math.sqrt(diff / norm)


def _stop_reason(change: float, tol: float, should_stop) -> str | None:
    if not math.isfinite(change):
        return "non-finite"
    if tol > 0 and change < tol:
        return "tolerance"
    return should_stop() if should_stop is not None else None
