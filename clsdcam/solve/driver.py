"""The driver: runs any algorithm (:mod:`clsdcam.algorithms`) on a problem, phase by phase, and owns everything
around its iterations: the history, the stopping rules and their reasons, Ctrl-C, the events its observers hear,
timing, and the checkpoints (:mod:`clsdcam.solve.checkpoints`).

    for each iteration k:  record = algorithm.iterate(problem)     (its numbers)
                           record["transforms"] = algorithm.transforms(problem)    (declared, not counted by it)
                           guard against divergence (back-off)
                           at k = 1, every ``objective_every`` and a phase's last: checkpoint F(x) (+ a forward)
                           history ← record; each observer.on_iteration(record, x, problem); stop?

Observers (:class:`Observer`, SCICO's ``itstat_insert_func`` as events) hear each iteration, the notes the code
around the loop makes (:meth:`Driver.note`: a skip taken, a space entered, a weight chosen) and the FFT work it
does between iterations (:meth:`Driver.work`: a subspace's power iteration, a full-step check); the solve's are
in :mod:`clsdcam.solve.tracker`.

It stops after ``iters`` iterations, when the estimated relative distance to the limit
(:mod:`clsdcam.solve.convergence`, kept in the records as ``distance``) falls below ``converge`` ("converged"), when
the relative change ‖x⁺ − x‖/‖x⁺‖ falls below ``tol`` ("tolerance"), when the objective fell by less than
``plateau`` (relative) between two checkpoints ("plateau"), when ``should_stop`` says so, on Ctrl-C ("interrupted",
returning the best iterate), or after too many back-offs ("diverged"), and says why. Between phases the caller may
move the algorithm to another space (:meth:`Driver.move`) or change the objective (:meth:`Driver.rescore`);
:func:`minimize` is one phase from x0.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Any, Callable, Iterable

from ..algorithms import ALGORITHMS
from .checkpoints import Checkpoints
from .convergence import DistanceEstimate


@dataclass(frozen=True)
class Rules:
    """When to stop, how often to check the objective, whether to restart momentum (algorithms that have it)."""

    converge: float = 0.0
    tol: float = 0.0
    plateau: float = 0.0
    objective_every: int = 10
    restart: bool = True


class Observer:
    """What a driver tells those who watch it; each event is a no-op here, an observer overrides those it needs.
    Observers hear each event in the order they were added."""

    def on_iteration(self, record: dict, x, problem) -> None:
        """After each iteration on ``problem``, its record in the history already (a Ctrl-C inside keeps it)."""

    def on_note(self, line: str) -> None:
        """A line for the solve's report."""

    def on_work(self, transforms: int) -> None:
        """2-D FFTs done between iterations (one ∇f costs ``problem.transforms()``)."""


class Driver:
    """One solve's loop around ``algorithm`` (whose x is the start), with ``rules``; ``objective`` F (or None: no
    checkpoints) for the space it starts in; ``observers`` hear its events."""

    def __init__(self, algorithm, rules: Rules = Rules(), objective: Callable[[Any], float] | None = None,
                 observers: Iterable[Observer] = ()):
        self._start = time.perf_counter()
        self.algorithm = algorithm
        self.rules = rules
        self.history: list[dict] = []
        self.checkpoints = Checkpoints(algorithm, objective, algorithm.backend.dtype)
        self.estimate = DistanceEstimate()
        self.observers = list(observers)

    def observe(self, observer: Observer):
        """``observer`` hears every event from now on, after those added before it."""
        self.observers.append(observer)

    def note(self, *lines: str | None):
        """Tell the observers each line that is not None."""
        for line in filter(None, lines):
            for observer in self.observers:
                observer.on_note(line)

    def work(self, transforms: int):
        """Tell the observers of 2-D FFTs done outside the iterations."""
        for observer in self.observers:
            observer.on_work(transforms)

    @property
    def x(self):
        return self.algorithm.x

    @property
    def step(self) -> float:
        return self.algorithm.step

    @property
    def iterations(self) -> int:
        return len(self.history)

    def run(self, problem, iters: int, should_stop: Callable[[], str | None] | None = None) -> str | None:
        """Up to ``iters`` more iterations on ``problem``; the reason it stopped early, or None."""
        try:
            for i in range(iters):
                record = self._iteration(problem, last=i == iters - 1)
                self.history.append(record)        # counted before the observers: a Ctrl-C inside them keeps it
                for observer in self.observers:
                    observer.on_iteration(record, self.x, problem)
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
        self.estimate.restart()

    def widen_stop(self, converge: float):
        """Stop from now on when the estimated distance is below ``converge`` (the rules' own where that is wider,
        or where the rule is off)."""
        if 0 < self.rules.converge < converge:
            self.rules = replace(self.rules, converge=converge)

    def narrow_stop(self, converge: float):
        """Stop from now on only when the estimated distance is below ``converge`` (the rules' own where that is
        narrower, or where the rule is off)."""
        if 0 < converge < self.rules.converge:
            self.rules = replace(self.rules, converge=converge)

    def rescore(self, objective):
        """Go on from the same iterates, momentum and step under another objective (e.g. auto weights chosen)."""
        self.checkpoints.rescore(objective)
        self.estimate.restart()

    def reroute(self, line: str | None):
        """The algorithm's iteration changed between two iterations (e.g. new penalties), said in ``line``: the
        distance estimate forgets the steps of the old road (None: nothing changed, nothing forgotten)."""
        if line is not None:
            self.note(line)
            self.estimate.restart()

    def _iteration(self, problem, last: bool) -> dict:
        k = self.iterations + 1
        numbers = self.algorithm.iterate(problem)
        record = self.checkpoints.guard({**numbers, "transforms": self.algorithm.transforms(problem),
                                         "step": self.algorithm.step, "rollback": False, "backoff": False})
        record["iteration"] = k
        if self.checkpoints.active and (k % self.rules.objective_every == 0 or k == 1 or last):
            record.update(self.checkpoints.check())
            record["transforms"] += problem.transforms() // 2      # F(x): one forward
        record["objective"] = record.get("objective", math.nan)
        if self.rules.converge > 0:
            self.estimate.add(record["change"])
            record["distance"] = self.estimate.distance
        record["seconds"] = time.perf_counter() - self._start
        return record

    def _stop_reason(self, record: dict, should_stop) -> str | None:
        rules = self.rules
        if self.checkpoints.diverged:
            return "diverged"
        if rules.converge > 0 and record["distance"] < rules.converge:
            return "converged"
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


class Callback(Observer):
    """An ``on_iteration(record, x)`` function as an observer (:func:`minimize`'s)."""

    def __init__(self, function: Callable[[dict, Any], None]):
        self.function = function

    def on_iteration(self, record: dict, x, problem) -> None:
        self.function(record, x)


def minimize(gradient_step: Callable, prox: Callable, backend, x0, *, step: float, iters: int,
             algorithm: str = "fista", objective: Callable[[Any], float] | None = None,
             on_iteration: Callable[[dict, Any], None] | None = None,
             should_stop: Callable[[], str | None] | None = None, **rules) -> Run:
    """Run ``algorithm`` from x0 (a backend array, not modified) in one phase; ``rules``: the fields of
    :class:`Rules`."""
    rules = Rules(**rules)
    observers = [Callback(on_iteration)] if on_iteration is not None else []
    driver = Driver(ALGORITHMS[algorithm](backend, x0, step, rules), rules, objective, observers)
    reason = driver.run(Functions(gradient_step, prox), iters, should_stop) or "iterations"
    return Run(x=driver.x, iterations=driver.iterations, stop_reason=reason, step=driver.step, history=driver.history)
