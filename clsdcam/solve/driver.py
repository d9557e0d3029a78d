"""The driver: runs any algorithm (:mod:`clsdcam.algorithms`) on a problem, phase by phase, and owns everything
around its iterations: the history, the stopping rules and their reasons, Ctrl-C, the per-iteration callback
(progress, snapshots), timing, and the checkpoints (:mod:`clsdcam.solve.checkpoints`).

    for each iteration k:  record = algorithm.iterate(problem)     (its numbers)
                           guard against divergence (back-off)
                           at k = 1, every ``objective_every`` and a phase's last: checkpoint F(x) (+ a forward)
                           history ← record; on_iteration(record, x); stop?

It stops after ``iters`` iterations, when the relative change ‖x⁺ − x‖/‖x⁺‖ falls below ``tol``
("tolerance"), when the objective fell by less than ``plateau`` (relative) between two checkpoints ("plateau"),
when ``should_stop`` says so, on Ctrl-C ("interrupted", returning the best iterate), or after too many back-offs
("diverged"), and says why. Between phases the caller may move the algorithm to another space (:meth:`Driver.move`)
or change the objective (:meth:`Driver.rescore`); :func:`minimize` is one phase from x0.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any, Callable

from ..algorithms import ALGORITHMS
from .checkpoints import Checkpoints


@dataclass(frozen=True)
class Rules:
    """When to stop, how often to check the objective, whether to restart momentum (algorithms that have it)."""

    tol: float = 0.0
    plateau: float = 0.0
    objective_every: int = 10
    restart: bool = True


class Driver:
    """One solve's loop around ``algorithm`` (whose x is the start), with ``rules``; ``objective`` F (or None: no
    checkpoints) for the space it starts in."""

    def __init__(self, algorithm, rules: Rules = Rules(), objective: Callable[[Any], float] | None = None):
        self._start = time.perf_counter()
        self.algorithm = algorithm
        self.rules = rules
        self.history: list[dict] = []
        self.checkpoints = Checkpoints(algorithm, objective, algorithm.backend.dtype)

    @property
    def x(self):
        return self.algorithm.x

    @property
    def step(self) -> float:
        return self.algorithm.step

    @property
    def iterations(self) -> int:
        return len(self.history)

    def run(self, problem, iters: int, on_iteration: Callable[[dict, Any], None] | None = None,
            should_stop: Callable[[], str | None] | None = None) -> str | None:
        """Up to ``iters`` more iterations on ``problem``; the reason it stopped early, or None."""
        try:
            for i in range(iters):
                record = self._iteration(problem, last=i == iters - 1)
                self.history.append(record)        # counted before the callback: a Ctrl-C inside it keeps it
                if on_iteration is not None:
                    on_iteration(record, self.x)
                reason = self._stop_reason(record, should_stop)
                if reason:
                    return reason
        except KeyboardInterrupt:
            self.checkpoints.restore()
            return "interrupted"
        return None

    def move(self, mapping: Callable[[Any], Any], step: float, objective=None, evaluate: bool = True):
        """The algorithm's iterates through ``mapping`` into another space, with ``step`` and ``objective`` there;
        ``evaluate=False``: F of the moved x is not computed (the first checkpoint sets the best)."""
        self.algorithm.move(mapping)
        self.algorithm.step = step
        self.checkpoints.enter(objective, evaluate)

    def rescore(self, objective):
        """Go on from the same iterates, momentum and step under another objective (e.g. auto weights chosen)."""
        self.checkpoints.rescore(objective)

    def _iteration(self, problem, last: bool) -> dict:
        k = self.iterations + 1
        numbers = self.algorithm.iterate(problem)
        record = self.checkpoints.guard({**numbers, "step": self.algorithm.step, "rollback": False, "backoff": False})
        record["iteration"] = k
        if self.checkpoints.active and (k % self.rules.objective_every == 0 or k == 1 or last):
            record.update(self.checkpoints.check())
            record["transforms"] += problem.transforms() // 2      # F(x): one forward
        record["objective"] = record.get("objective", math.nan)
        record["seconds"] = time.perf_counter() - self._start
        return record

    def _stop_reason(self, record: dict, should_stop) -> str | None:
        rules = self.rules
        if self.checkpoints.diverged:
            return "diverged"
        if rules.tol > 0 and not record.get("rollback") and record["change"] < rules.tol:
            return "tolerance"
        if rules.plateau > 0 and math.isfinite(record["objective"]) and not record.get("rollback"):
            fall = self.checkpoints.fall_since_last(record["objective"])
            if record["iteration"] > 1 and fall < rules.plateau * abs(record["objective"]):
                return "plateau"
        return should_stop() if should_stop is not None else None


@dataclass
class Run:
    """What :func:`minimize` returns."""

    x: Any
    iterations: int
    stop_reason: str
    step: float
    history: list[dict] = field(default_factory=list)


class Functions:
    """A problem made of two callables: ``gradient_step(y, out, step) -> f(y)`` and ``prox(z, step, out)``."""

    def __init__(self, gradient_step: Callable, prox: Callable):
        self.gradient_step, self.prox = gradient_step, prox

    def transforms(self) -> int:
        return 0


def minimize(gradient_step: Callable, prox: Callable, backend, x0, *, step: float, iters: int,
             algorithm: str = "fista", objective: Callable[[Any], float] | None = None,
             on_iteration: Callable[[dict, Any], None] | None = None,
             should_stop: Callable[[], str | None] | None = None, **rules) -> Run:
    """Run ``algorithm`` from x0 (a backend array, not modified) in one phase; ``rules``: the fields of
    :class:`Rules`."""
    rules = Rules(**rules)
    driver = Driver(ALGORITHMS[algorithm](backend, x0, step, rules), rules, objective)
    reason = driver.run(Functions(gradient_step, prox), iters, on_iteration, should_stop) or "iterations"
    return Run(x=driver.x, iterations=driver.iterations, stop_reason=reason, step=driver.step, history=driver.history)
