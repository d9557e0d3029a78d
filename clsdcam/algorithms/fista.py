"""FISTA (Beck & Teboulle 2009) as one step object; the driver (:mod:`clsdcam.solve.driver`) runs it. With step s:

    z   = y − s·∇f(y)                       (problem.gradient_step)
    x⁺  = prox_{s·g}(z)                     (problem.prox)
    t⁺  = (1 + √(1 + 4t²)) / 2
    y⁺  = x⁺ + ((t − 1)/t⁺)·(x⁺ − x)         (extrapolate)

with adaptive restart (O'Donoghue & Candès 2015, gradient scheme): when ⟨y − x⁺, x⁺ − x⟩ > 0 the momentum
points uphill, so t ← 1 (y⁺ = x⁺). The two vector passes are the backend's fusions ``fista_stats`` and
``extrapolate`` when it has them, else built from its primitives (:func:`stats_from_primitives`,
:func:`extrapolate_from_primitives`): a backend without them still runs.
"""
from __future__ import annotations

import math

from .base import Algorithm, place, ratio


def next_momentum(t: float) -> float:
    """t⁺ = (1 + √(1 + 4t²)) / 2  (the authors' Python has 1 + √(1 + 4t²)/2, a bug)."""
    return (1.0 + math.sqrt(1.0 + 4.0 * t * t)) / 2.0


def stats_from_primitives(backend, x_new, x_old, y, scratch) -> tuple[float, float, float]:
    """(‖x⁺ − x‖², ‖x⁺‖², ⟨y − x⁺, x⁺ − x⟩) with d = x⁺ − x in ``scratch`` and y − x⁺ formed in y itself (y is
    rewritten by the extrapolation next: the difference is taken before the products, with no cancellation)."""
    d = backend.axpy(-1.0, x_old, x_new, out=scratch)
    e = backend.axpy(-1.0, x_new, y, out=y)
    return backend.vdot(d, d), backend.vdot(x_new, x_new), backend.vdot(e, d)


def extrapolate_from_primitives(backend, x_new, x_old, beta: float, out, scratch):
    """out = x⁺ + β·(x⁺ − x), the difference in ``scratch`` (``out`` may alias x_old, not x_new)."""
    d = backend.axpy(-1.0, x_old, x_new, out=scratch)
    return backend.axpy(beta, d, x_new, out=out)


class Fista(Algorithm):
    """FISTA's iterates (x, x_prev, y, z) and momentum t (see the module docstring)."""

    name = "fista"

    def __init__(self, backend, x0, step: float, rules):
        super().__init__(backend, x0, step, rules)
        self.restart = rules.restart
        self.t = 1.0
        self.x = self.x_prev = self.y = self.z = None
        self._place([x0] * 4)
        self._fused_stats = getattr(backend, "fista_stats", None)
        self._fused_extrapolate = getattr(backend, "extrapolate", None)

    def iterate(self, problem) -> dict:
        """One FISTA step with the adaptive restart test."""
        data = problem.gradient_step(self.y, self.z, self.step)
        self.x, self.x_prev = self.x_prev, self.x
        problem.prox(self.z, self.step, self.x)
        step_sq, norm_sq, slope = self._stats()            # ‖x⁺ − x‖², ‖x⁺‖², ⟨y − x⁺, x⁺ − x⟩
        uphill = self.restart and slope > 0
        if uphill:
            self.t = 1.0
        t_next = next_momentum(self.t)
        self._extrapolate((self.t - 1.0) / t_next)       # y = x⁺ + β(x⁺ − x)
        self.t = t_next
        return {"data": data, "change": ratio(step_sq, norm_sq), "momentum": self.t, "restart": bool(uphill)}

    def reset(self, point) -> None:
        for array in (self.x, self.x_prev, self.y):
            self.backend.copy(point, out=array)
        self.t = 1.0

    def move(self, mapping) -> None:
        """x, x_prev and y through ``mapping``. One that keeps their shape (``keeps_shape``: a basis renewed at the
        same rank) writes each into the array the one before it freed, z's first: no new cubes, no copies."""
        if not getattr(mapping, "keeps_shape", False):
            x, x_prev, y = (mapping(a) for a in (self.x, self.x_prev, self.y))
            return self._place([x, x_prev, y, x])
        free = self.z
        for name in ("x", "x_prev", "y"):
            old = getattr(self, name)
            setattr(self, name, mapping(old, out=free))
            free = old
        self.z = free

    def _stats(self) -> tuple[float, float, float]:
        if self._fused_stats is not None:
            return self._fused_stats(self.x, self.x_prev, self.y)
        return stats_from_primitives(self.backend, self.x, self.x_prev, self.y, self.z)   # z is free after the prox

    def _extrapolate(self, beta: float):
        if self._fused_extrapolate is not None:
            return self._fused_extrapolate(self.x, self.x_prev, beta, out=self.y)
        return extrapolate_from_primitives(self.backend, self.x, self.x_prev, beta, self.y, self.z)

    def _place(self, sources):
        """x, x_prev, y, z ← copies of ``sources`` (z: scratch, first written by the gradient step)."""
        self.x, self.x_prev, self.y, self.z = place(self.backend, [self.x, self.x_prev, self.y, self.z], sources)
