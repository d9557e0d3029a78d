"""What an algorithm is to the driver (:mod:`clsdcam.driver`): one iteration at a time on a problem, and its own
iterates.

An algorithm minimises F(x) = f(x) + g(x) for a problem (:class:`clsdcam.problem.Problem`) that offers

    problem.gradient_step(y, out, step) -> f(y)      out = y − step·∇f(y)
    problem.prox(z, step, out)                        out = prox_{step·g}(z)
    problem.transforms()                              2-D FFTs one ∇f costs

and keeps whatever iterates it needs. To the driver it is:

* ``backend``: the backend its arrays live on; ``x``: the current iterate (what the checkpoints score and the
  solve returns); ``step``: its step size (the checkpoints halve it on a back-off);
* ``iterate(problem) -> dict``: one iteration; the record's numbers, at least ``data`` (f where the gradient was
  taken), ``change`` (‖x⁺ − x‖/‖x⁺‖) and ``transforms`` (the FFTs it did), plus its own (FISTA: ``momentum``,
  ``restart``);
* ``reset(point)``: every iterate to ``point``, any momentum afresh (the checkpoints' rollback);
* ``move(mapping)``: every iterate through ``mapping`` (a change of space, e.g. onto a spectral basis), any
  momentum kept. A mapping with ``keeps_shape`` true also takes ``out=``, an array of the iterates' shape other
  than its input, to write into (``clsdcam.spaces.BandMixing``).

What it cannot do yet it declares as class attributes, which ``Settings`` and ``--backend auto`` read (absent: no
limit): ``backends`` (the backend names it runs on; both built-in algorithms run on both), ``band_space_only`` (no
``--subspace`` or ``--rank``) and ``priors`` (the prior names it has a step for). ``field_buffers``, the field cubes
it keeps, sizes the device's memory plan (absent: FISTA's).

Optionally, an algorithm with more state than its iterates keeps it across a video's frames: ``carry()`` returns it
(or None) for :class:`clsdcam.state.SolverState`, and ``resume(carried, factor)`` takes it over before the first
iteration, every array times ``factor`` (ADMM's splits and duals).

A constructor ``(backend, x0, step, rules)`` copies x0 into its iterates (``rules``: :class:`clsdcam.driver.Rules`).
A new algorithm is one module and one line in :data:`clsdcam.algorithms.ALGORITHMS`.
"""
from __future__ import annotations

import math
from typing import Any, Protocol, Sequence


class Algorithm(Protocol):
    backend: Any
    x: Any
    step: float

    def iterate(self, problem) -> dict:
        """One iteration; the record's numbers (``data``, ``change``, ``transforms``, and the algorithm's own)."""

    def reset(self, point) -> None:
        """Every iterate to ``point`` (copied), momentum afresh."""

    def move(self, mapping) -> None:
        """Every iterate through ``mapping`` (into another space), momentum kept."""


def place(backend, previous: Sequence, sources: Sequence) -> list:
    """Copies of ``sources`` (one per slot of ``previous``) written into ``previous``'s arrays when they all have the
    sources' shape and dtype and none of them is a source (a space of the same size: no new cubes, whose first touch
    costs ~40 ms each for a 64×256×320 cube on a 2-core VM), else into new arrays. Aliasing is told by identity: a
    mapping must return new arrays or the iterates themselves, not views of them."""
    like = sources[0]
    same = all(a is not None and a.shape == like.shape and a.dtype == like.dtype for a in previous)
    if not same or any(a is s for a in previous for s in sources):
        previous = [None] * len(previous)
    return [backend.copy(source, out=out) for source, out in zip(sources, previous)]


def ratio(diff: float, norm: float) -> float:
    """√(diff/norm): 0 when both are zero (a relative change)."""
    if norm == 0.0:
        return 0.0 if diff == 0.0 else math.inf
    return math.sqrt(diff / norm) if math.isfinite(diff) and math.isfinite(norm) else math.inf
