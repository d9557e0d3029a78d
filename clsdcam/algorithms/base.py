"""What an algorithm is to the driver (:mod:`clsdcam.solve.driver`): one iteration at a time on a problem, and its own
iterates; every algorithm subclasses :class:`Algorithm`, whose class attributes say what it can do.

An algorithm minimises F(x) = f(x) + g(x) for a problem (:class:`clsdcam.solve.problem.Problem`) that offers

    problem.gradient_step(y, out, step) -> f(y)      out = y − step·∇f(y)
    problem.prox(z, step, out)                        out = prox_{step·g}(z)
    problem.transforms()                              2-D FFTs one ∇f costs

and, for an algorithm with sub-problems of its own (ADMM's splits), the parts they are built from: ``problem.model``
(A), ``problem.b``, ``problem.priors``, ``problem.filters``, ``problem.subspace`` (None in band space) and
``problem.shared``, a store kept by the solver across its solves (what depends on the calibration alone is built
once there). To the driver an algorithm is:

* ``backend``: the backend its arrays live on; ``x``: the current iterate (what the checkpoints score and the
  solve returns); ``step``: its step size (the checkpoints halve it on a back-off);
* ``iterate(problem) -> dict``: one iteration; the record's numbers, at least ``data`` (f where the gradient was
  taken) and ``change`` (‖x⁺ − x‖/‖x⁺‖), plus its own (FISTA: ``momentum``, ``restart``);
* ``transforms(problem) -> int``: the 2-D FFTs an iteration on ``problem`` does, declared (by default one ∇f's:
  ``problem.transforms()``), read by the driver after each iteration into the record's ``transforms``: an
  algorithm counts no work of its own;
* ``reset(point)``: every iterate to ``point``, any momentum afresh (the checkpoints' rollback);
* ``move(mapping)``: every iterate through ``mapping`` (a change of space, e.g. onto a spectral basis), any
  momentum kept. A mapping with ``keeps_shape`` true also takes ``out=``, an array of the iterates' shape other
  than its input, to write into (``clsdcam.solve.spaces.BandMixing``).

A constructor ``(backend, x0, step, rules)`` copies x0 into its iterates (``rules``:
:class:`clsdcam.solve.driver.Rules`).
A new algorithm is one module (or one folder, with its sub-problems) and one line in
:data:`clsdcam.algorithms.ALGORITHMS`.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

from ..errors import InputError


class Algorithm:
    """The base of every algorithm: what it can do, with defaults, read by the solver, the settings and the
    checkpoints from here alone (SCICO's ``Optimizer``, SigPy's ``Alg``)."""

    name = ""
    monotone = True
    """Its F never rises but by round-off: the checkpoints roll a rise back. False (ADMM): a rise is kept, and the
    best iterate is what Ctrl-C returns."""
    field_buffers: int | None = None
    """The field cubes it keeps, for the device's memory plan (``cl_devices.problem_bytes``); None: FISTA's."""
    band_space_only = False
    """True: no ``--subspace`` or ``--rank`` (``move`` refuses a change of space)."""
    priors: tuple[str, ...] | None = None
    """The prior names it has a step for; None: every prior."""
    converges_soonest = False
    """True: ``--algorithm auto`` runs it for a solve run until converged (``--iters auto``) whenever it can run the
    settings (docs/convergence.md)."""
    backends: tuple[str, ...] | None = None
    """The backend names it runs on (``--backend auto`` picks NumPy when OpenCL is not one); None: every backend."""
    point_like_below = 0.0
    """The mean over the peak of its iterate at the auto weights' iteration below which ``auto`` takes the scene as
    point-like (:mod:`clsdcam.solve.auto_weights`); 0: never (the threshold is measured per algorithm, since each
    one's early iterate spreads the light differently)."""
    widely_lit_above = math.inf
    """The mean over the peak of the same iterate at or above which ``auto`` takes the scene as widely lit; ∞: never
    (measured per algorithm, as ``point_like_below``; read only where that is set)."""

    backend: Any
    x: Any
    step: float

    def __init__(self, backend, x0, step: float, rules):
        self.backend, self.step = backend, step

    def iterate(self, problem) -> dict:
        """One iteration; the record's numbers (``data``, ``change``, and the algorithm's own)."""
        raise NotImplementedError

    def transforms(self, problem) -> int:
        """The 2-D FFTs one iteration on ``problem`` does (read after it): one gradient's by default."""
        return problem.transforms()

    def reset(self, point) -> None:
        """Every iterate to ``point`` (copied), momentum afresh."""
        raise NotImplementedError

    def move(self, mapping) -> None:
        """Every iterate through ``mapping`` (into another space), momentum kept."""
        raise InputError(f"--algorithm {self.name} runs in band space: no --subspace or --rank")

    def point_like(self, few_points: bool = False) -> str | None:
        """The auto weights' probe found the scene point-like (:mod:`clsdcam.solve.auto_weights`), and whether it is a
        scene of ``few_points`` (a few points in good light, not of the fewest, are told point-like, and told again
        at the recount: :meth:`few_points_to_lighten`): an algorithm with a setting of its own for such scenes takes it
        (ADMM: a lighter non-negativity penalty, on a few points wider TV thresholds) and returns a line for the
        solve's notes that says what it did. Nothing by default (None)."""

    def lit_spots(self) -> str | None:
        """The scene :meth:`point_like` was told is of a few points was counted again later and is one of lit spots
        (:mod:`clsdcam.solve.auto_weights`, its recount): an algorithm that took a setting for a few points takes the
        one for a point-like scene instead (ADMM: its penalties for one, the TV balanced again) and returns a line
        that says so. Nothing by default (None)."""

    def few_points_to_lighten(self) -> str | None:
        """The scene :meth:`point_like` was told is point-like, read in good light as a few points not of the fewest,
        was counted again later and is one of a few points (the recount): an algorithm with a setting for them takes
        it (ADMM: the few points' penalties, every one lighter, the TV balanced again) and returns a line that says
        so. Nothing by default (None)."""

    def carry(self):
        """What a video's next frame resumes from besides its iterate (:class:`clsdcam.solve.state.SolverState`), or
        None: an algorithm with more state than its iterates (ADMM's splits and duals) returns it. Its ``moved()``
        is what a frame whose field moved resumes from instead (:func:`clsdcam.batch.motion.predict_state`), or
        None."""
        return None

    def resume(self, carried, factor: float) -> None:
        """Take over ``carried`` (a previous solve's :meth:`carry`, or what its ``moved()`` kept), every array times
        ``factor`` (its units to this solve's), before the first iteration. Nothing to take over by default."""


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
