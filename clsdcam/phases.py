"""The solver's phases: band space, then (with ``--subspace`` or ``--rank R``) the spectral subspace once the
scene's spectra have settled.

The default stays in band space: no signal read during a solve certifies that a basis holds the spectra the full
problem would find (on scenes of many smooth, overlapping spectra the automatic subspace cost 3.6–5.1° of
spectral angle at full size, with a basis of 21 vectors for 8 true spectra), and the accuracy rule
(docs/accuracy.md) admits no loss. ``Settings.subspace`` turns the automatic subspace on, as a speed option.

The basis is read from the spectra as the spectral angle weighs them: the unit spectra of the lit pixels
of the sensor window (:func:`clsdcam.subspace.lit_shapes`), so a faint object's spectrum counts as much
as a bright one's; ``rank_for(ENTRY_TAIL)`` directions leave at most that mean sin² of them outside.

1. Band space for ``WARMUP`` iterations, then until the spectra settle: every ``SETTLE_EVERY``
   iterations the basis is read again, and the solve moves on once the previous basis holds the current
   lit spectra within ``SETTLED`` (mean sin²) of the current one, and at most K/2 vectors hold them. A
   subspace entered before then freezes spectra that band space is still finding (a faint line, a line
   at a weak filter's edge); spectra that never settle into K/2 directions are solved in band space.
   After a warm start the spectra are known: no warm-up; with ``--rank R`` WARMUP iterations only.
2. FISTA moves onto the basis (c = Bᵀx, ``--rank R``: R vectors) and goes on with A·B (4r FFTs per
   iteration). A basis of more than K/2 vectors would not pay: the solve stays in band space.
3. Every ``CHECK_EVERY`` iterations one full-space proximal-gradient step from v = B·c,
   x⁺ = prox(v − ∇f(v)/L), updates the basis: its lit spectra are read again, at a rank that never
   falls (spectra the scene has shown stay: "core" rank) but grows when they need more directions;
   when the full step also lowers the data term ½‖Av − b‖² by more than ``WIDEN_GAIN`` (relative), the
   measurement holds content the basis cannot represent, and up to as many directions again are added:
   those the step turns the lit spectra towards (:func:`clsdcam.subspace.turning_directions`). FISTA
   moves to the new basis with its momentum. When r would pass K/2 the solve returns to band space.

Weights set to ``auto`` (:mod:`clsdcam.priors`) start at their rule's start and are chosen at iteration
``AUTO_AT`` from the noise level of that iterate's residual (:mod:`clsdcam.noise`), in every space
(``--no-skip`` too); FISTA goes on with its momentum under the new objective.

Every phase, check and widening is counted in the history (``rank``, ``transforms``) and the skip report.
"""
from __future__ import annotations

import hashlib

import numpy as np

from .interrupts import held_interrupt
from .noise import residual_noise
from .problem import Problem
from .skips import subspace_line
from .subspace import Spectra, SpectralSubspace, lit_shapes, turning_directions
from .tracker import Tracker

WARMUP = 10
SETTLE_EVERY = 10
SETTLED = 5e-3             # the previous basis holds the spectra this close to the current one: settled
ENTRY_TAIL = 5e-3          # the basis leaves at most this mean sin² of the lit spectra outside
CHECK_EVERY = 25
WIDEN_GAIN = 1e-2
AUTO_AT = 30               # auto weights are chosen from the noise of this iteration's residual
MAX_RANK_FRACTION = 0.5


def held(shapes: np.ndarray, basis: np.ndarray) -> float:
    """Mean cos² of unit spectra (K, N) in span(basis): 1 − their mean sin² outside it."""
    return float(np.mean(np.sum((basis.T @ shapes) ** 2, axis=0))) if shapes.shape[1] else 1.0


class Phases:
    """Runs one solve's FISTA loop through its spaces (see the module docstring)."""

    def __init__(self, solver, loop, tracker: Tracker, priors: list, iters: int, should_stop=None):
        self.solver = solver
        self.settings = solver.settings
        self.iters = iters                          # this solve's budget
        self.should_stop = should_stop              # FISTA's extra stopping rule (e.g. a fit reached), or None
        self.backend = solver.backend
        self.loop = loop
        self.tracker = tracker
        self.priors = priors
        self.n_bands = solver.model.n_bands
        self.problem: Problem | None = None         # the space FISTA's iterates are in
        self._full: Problem | None = None
        self._buffers: dict = {}
        self._lipschitz = solver.lipschitz          # of the space the loop is in
        self._core = 0                              # directions the scene's spectra have needed so far
        self._refreshes = 0                         # bases re-read at the same rank
        self.chosen: dict = {}                      # what auto weights chose, for the result's attributes

    def run(self, problem: Problem, warm_started: bool, basis: np.ndarray | None = None, core: int = 0
            ) -> tuple[str, Problem]:
        """(stop reason, the problem the final iterate lives in); ``basis`` (and its ``core`` rank): a previous
        solve's subspace, entered at once."""
        self.problem = problem
        try:
            return self._run_phases(warm_started, basis, core), self.problem
        except KeyboardInterrupt:     # between FISTA runs; moves between spaces finish first (held_interrupt)
            return "interrupted", self.problem

    def _run_phases(self, warm_started: bool, basis, core: int) -> str:
        iters, loop = self.iters, self.loop
        if self._subspace_allowed() and basis is not None:
            with held_interrupt():
                self.problem = self._enter_basis(basis, max(core, 1), "carried from the previous solve")
        elif self._subspace_allowed():
            reason = None if warm_started else self._warm_up()
            if reason:
                return reason
            if loop.iterations < iters:
                with held_interrupt():
                    self.problem = self._enter_subspace(self.problem)
        while loop.iterations < iters:
            left = iters - loop.iterations
            checking = self.problem.subspace is not None
            reason = self._run(self.problem, min(CHECK_EVERY, left) if checking else left)
            if reason:
                return reason
            if checking and loop.iterations < iters:
                with held_interrupt():
                    self.problem = self._check_width(self.problem)
        return "iterations"

    def _warm_up(self) -> str | None:
        """Band space for WARMUP iterations, then until consecutive bases settle; a stop reason or None."""
        iters, loop = self.iters, self.loop
        reason = self._run(self.problem, min(WARMUP, iters))
        if self.settings.rank:            # the user chose the basis's size: no waiting for the spectra
            return reason
        previous = self._window_spectra()[1]
        while not reason and loop.iterations < iters:
            reason = self._run(self.problem, min(SETTLE_EVERY, iters - loop.iterations))
            _, current, shapes = self._window_spectra()
            settled = held(shapes, current) - held(shapes, previous) <= SETTLED
            if settled and current.shape[1] <= self.n_bands * MAX_RANK_FRACTION:
                break
            previous = current
        return reason

    def _window_spectra(self) -> tuple[Spectra, np.ndarray, np.ndarray]:
        """(spectra, their basis at the entry rank (or --rank), the lit unit spectra) of the band-space iterate."""
        shapes = lit_shapes(self.solver.model.window(self.loop.x))
        spectra = Spectra.of_shapes(shapes)
        return spectra, spectra.basis(self.settings.rank or spectra.rank_for(ENTRY_TAIL)), shapes

    def refreshes_line(self) -> str | None:
        """How often the basis was read again at the same rank (for the skip report)."""
        return (f"subspace basis re-read from a full step's spectra {self._refreshes} times at the same rank"
                if self._refreshes else None)

    def _run(self, problem: Problem, iters: int) -> str | None:
        """Up to ``iters`` iterations in ``problem``'s space, choosing auto weights on the way at AUTO_AT."""
        loop, pending = self.loop, [prior for prior in self.priors if prior.auto]
        if pending and loop.iterations < AUTO_AT <= loop.iterations + iters:
            first = AUTO_AT - loop.iterations
            reason = loop.run(problem.gradient_step, problem.prox, first, self.tracker.on(problem), self.should_stop)
            if reason:
                return reason
            self._choose_weights(problem, pending)
            iters -= first
        return loop.run(problem.gradient_step, problem.prox, iters, self.tracker.on(problem), self.should_stop)

    def _choose_weights(self, problem: Problem, pending: list):
        """Auto weights from the noise σ̂ of the current residual (b / max|b|: σ̂ relative to max|b|)."""
        noise = residual_noise(self.backend.to_host(problem.residual(self.loop.x)))
        for prior in pending:
            prior.set_relative(prior.auto_weight.for_noise(noise))
            prior.auto = False
            self.tracker.report.lines.append(
                f"{prior.name}: auto, {prior.relative:.3g} (noise σ ≈ {noise:.3g} of max|b|, from the residual at "
                f"iteration {self.loop.iterations})")
        self.chosen["noise_estimate"] = noise
        self.loop.change_objective(problem.objective)

    def _subspace_allowed(self) -> bool:
        s = self.settings
        if not s.skip:
            return False
        if s.rank:
            return s.rank < self.n_bands
        return s.subspace and self.n_bands * MAX_RANK_FRACTION >= 2      # fewer bands: r ≤ K/2 saves too little

    # ---- entering the subspace --------------------------------------------------------------
    def _enter_subspace(self, problem: Problem) -> Problem:
        spectra, basis, _ = self._window_spectra()
        rank = basis.shape[1]
        report = self.tracker.report
        if rank > self.n_bands * MAX_RANK_FRACTION and not self.settings.rank:
            report.lines.append(subspace_line(self.n_bands, self.n_bands, 0, 1.0,
                                              f"{rank} directions hold the spectra: band space is cheaper"))
            return problem
        how = f"--rank {rank}" if self.settings.rank else \
            f"spectra settled; a mean sin² of at most {ENTRY_TAIL:g} of the lit spectra outside"
        return self._enter_basis(basis, rank, how, spectra.captured(rank))

    def _enter_basis(self, basis: np.ndarray, core: int, how: str, captured: float = 1.0) -> Problem:
        """FISTA onto ``basis`` (c = Bᵀx), said in the skip report; the first checkpoint in the subspace sets the best
        iterate (see :meth:`_move`)."""
        self._core = core
        subspace = self._subspace_problem(basis)
        self.loop.change_space(subspace.subspace.project, self._step(subspace.subspace.lipschitz), subspace.objective,
                               evaluate=False)
        self.tracker.report.lines.append(subspace_line(basis.shape[1], self.n_bands, self.loop.iterations + 1,
                                                       captured, how))
        return subspace

    # ---- what the next solve can carry ----------------------------------------------------------
    def basis(self) -> np.ndarray | None:
        """The basis of the space the solve ended in (None: band space)."""
        return None if self.problem.subspace is None else self.problem.subspace.basis

    def core(self) -> int:
        return self._core

    def step_factor(self) -> float:
        """The final step times the Lipschitz constant of its space (1 unless backed off)."""
        return self.loop.step * self._lipschitz

    def _subspace_problem(self, basis: np.ndarray, start=None) -> Problem:
        """The problem on ``basis``; its Lipschitz constant (a power iteration) is the solver's last one when the
        basis is the same (a stream's next frame carries its basis)."""
        key = hashlib.sha1(np.ascontiguousarray(basis, np.float64).tobytes()).hexdigest()
        known = self.solver.subspace_lipschitz
        sub = SpectralSubspace(self.solver.model, basis, self.priors, self.solver.calibration.filters, start,
                               known[1] if known and known[0] == key else None)
        self.solver.subspace_lipschitz = (key, sub.lipschitz)
        return Problem(sub.model, self.solver.b, sub.prox, sub.penalty, sub.rank, subspace=sub)

    def _step(self, lipschitz: float) -> float:
        """The step for a space of Lipschitz constant L: the loop's current step·L (step_scale, halved by any
        back-offs so far) over L, so back-offs carry across spaces; the space becomes the current one."""
        scale, self._lipschitz = self.loop.step * self._lipschitz, lipschitz
        return scale / lipschitz

    def _full_step(self) -> float:
        """The step of a full-space check from the current space (the current one does not change)."""
        return self.loop.step * self._lipschitz / self.solver.lipschitz

    # ---- widening -------------------------------------------------------------------------------
    def _check_width(self, problem: Problem) -> Problem:
        """One full proximal-gradient step from v = B·c: the basis read again from its lit spectra (never fewer
        directions than the scene has needed), widened when the step lowers the data term by WIDEN_GAIN."""
        sub, model = problem.subspace, self.solver.model
        full = self._full_problem()
        data = problem.data(self.loop.x)                         # its residual A·B·c − b = A·v − b stays in place
        step = self._full_step()
        v = sub.expand(self.loop.x)
        before = model.window(v)
        gradient_step = full.model.adjoint(problem.residual_buffer, out=self._cube("z"), y=v, step=step)
        stepped = full.prox(gradient_step, self._cube("stepped"), step)         # x⁺ = prox(v − step·Aᵀ(Av − b))
        gain = (data - full.data(stepped)) / data if data > 0 else 0.0
        self.tracker.count(problem.transforms() // 2 + full.transforms())      # A·B·c, then Aᵀr and A·x⁺
        spectra = Spectra.of_shapes(lit_shapes(model.window(stepped)))
        if self.settings.rank:
            return self._move(sub, spectra.basis(sub.rank))
        self._core = max(self._core, spectra.rank_for(ENTRY_TAIL))
        core = spectra.basis(self._core)
        turns = turning_directions(core, before, model.window(stepped), self._core if gain > WIDEN_GAIN else 0)
        basis, _ = np.linalg.qr(np.hstack([core, turns]))
        if basis.shape[1] > self.n_bands * MAX_RANK_FRACTION:
            return self._leave_subspace(problem, gain)
        if basis.shape[1] > sub.rank:
            self._note(f"subspace widened to {basis.shape[1]} at iteration {self.loop.iterations + 1}", gain)
        return self._move(sub, basis)

    def _move(self, subspace: SpectralSubspace, basis: np.ndarray) -> Problem:
        """FISTA onto another basis, c ↦ B'ᵀB·c (lossless when span(B') ⊇ span(B)), momentum kept.

        The mapped point does not become the best iterate: the subspace's iteration c⁺ = Bᵀ·prox(B·c − s∇) is not a
        proximal-gradient step on F(c) = f(Bc) + g(Bc) (its prox also clips B·c at zero, which F does not charge), so
        a projection can score an F the iteration never reaches again, and a checkpoint held to it rolls back for
        ever (the 96×128 target entered at iteration 91 with 32 vectors: PSNR frozen from iteration 100;
        ``tests/test_skips.py::test_a_late_entry_keeps_improving``). The first checkpoint in the new space sets the
        best."""
        mix = basis.T @ subspace.basis
        vector = getattr(subspace.model, "power_vector", None)      # none when its L was known (no power iteration)
        moved = self._subspace_problem(basis, start=None if vector is None else self.backend.bandmix(vector, mix))
        self.loop.change_space(lambda c: self.backend.bandmix(c, mix), self._step(moved.subspace.lipschitz),
                               moved.objective, evaluate=False)
        if basis.shape[1] == subspace.rank:
            self._refreshes += 1
        return moved

    def _leave_subspace(self, problem: Problem, gain: float) -> Problem:
        """Back to band space (v = B·c exactly), momentum kept: a wider basis would not pay."""
        full = self._full_problem()
        self.loop.change_space(lambda c: self.backend.copy(problem.to_field(c)), self._step(self.solver.lipschitz),
                               full.objective)
        self._note(f"subspace left for band space at iteration {self.loop.iterations + 1}", gain)
        return full

    def _note(self, what: str, gain: float):
        self.tracker.report.lines.append(f"{what} (a full step lowered the data term by {100 * gain:.1f}%)")

    def _full_problem(self) -> Problem:
        if self._full is None:
            self._full = self.solver.band_problem(self.priors)
        return self._full

    def _cube(self, name: str):
        """A band cube for the checks (allocated at the first)."""
        if name not in self._buffers:
            self._buffers[name] = self.backend.empty(self.solver.model.cube_shape)
        return self._buffers[name]
