"""The phases of one solve: the driver (:mod:`clsdcam.solve.driver`) runs the algorithm in band space, and, with
``--subspace`` or ``--rank R``, in spectral subspaces, as :mod:`clsdcam.solve.space_policy` decides; the hooks
(automatic
weights, :mod:`clsdcam.solve.auto_weights`) act between iterations. This module observes and acts; the decisions are the
policy's: it reads the spectra (every ``SETTLE_EVERY`` iterations during the warm-up, one full step every
``CHECK_EVERY`` in a subspace) and moves the algorithm's iterates between spaces (``driver.move``), the moves shielded
from Ctrl-C (:func:`clsdcam.interrupts.held_interrupt`). Every phase, check and widening is counted in the history
(``rank``, ``transforms``) and the skip report: each phase and widening is a note the driver's observers hear
(``driver.note``), and each new subspace's power iteration and each check's full step is work they count
(``driver.work``).
"""
from __future__ import annotations

import numpy as np

from . import space_policy as policy
from ..interrupts import held_interrupt
from .problem import Problem
from .skips import subspace_line
from .space_policy import Enter, Leave, Move, Stay, has_settled, on_check, on_entry, read, subspace_allowed
from .spaces import Spaces


class Phases:
    """Runs one solve's driver through its spaces (see the module docstring)."""

    def __init__(self, driver, spaces: Spaces, settings, iters: int, hooks=(), should_stop=None):
        self.driver = driver
        self.spaces = spaces
        self.rank = settings.rank                   # a fixed basis size, or 0
        self.allowed = subspace_allowed(settings.skip, settings.rank, settings.subspace, spaces.n_bands)
        self.iters = iters                          # this solve's budget
        self.hooks = hooks                          # objects with due_in(done, iters) and act(problem, driver)
        self.should_stop = should_stop              # the driver's extra stopping rule (e.g. a fit reached), or None
        self.problem: Problem = spaces.band         # the space the iterates are in
        self.lipschitz = spaces.lipschitz           # of that space
        self.core = 0                               # directions the scene's spectra have needed so far
        self._refreshes = 0                         # bases re-read at the same rank

    def run(self, warm_started: bool, basis: np.ndarray | None = None, core: int = 0) -> str:
        """The stop reason; ``basis`` (and its ``core`` rank): a previous solve's subspace, entered at once."""
        try:
            return self._run_phases(warm_started, basis, core)
        except KeyboardInterrupt:     # between runs; moves between spaces finish first (held_interrupt)
            return "interrupted"

    def _run_phases(self, warm_started: bool, basis, core: int) -> str:
        driver, iters = self.driver, self.iters
        if self.allowed and basis is not None:
            with held_interrupt():
                self._enter(Enter(basis, max(core, 1), "carried from the previous solve"))
        elif self.allowed:
            reason = None if warm_started else self._warm_up()
            if reason:
                return reason
            if driver.iterations < iters:
                with held_interrupt():
                    self._enter_subspace()
        while driver.iterations < iters:
            left = iters - driver.iterations
            checking = self.problem.subspace is not None
            reason = self._run(min(policy.CHECK_EVERY, left) if checking else left)
            if reason:
                return reason
            if checking and driver.iterations < iters:
                with held_interrupt():
                    self._check_width()
        return "iterations"

    def _warm_up(self) -> str | None:
        """Band space for WARMUP iterations, then until consecutive bases settle; a stop reason or None."""
        driver, iters = self.driver, self.iters
        reason = self._run(min(policy.WARMUP, iters))
        if self.rank:            # the user chose the basis's size: no waiting for the spectra
            return reason
        previous = self._read().basis
        while not reason and driver.iterations < iters:
            reason = self._run(min(policy.SETTLE_EVERY, iters - driver.iterations))
            current = self._read()
            if has_settled(previous, current, self.spaces.n_bands):
                break
            previous = current.basis
        return reason

    def _read(self):
        return read(self.spaces.window(self.driver.x), self.rank)

    def _run(self, iters: int) -> str | None:
        """Up to ``iters`` iterations in the current space; hooks due on the way act between iterations, the
        earliest first."""
        while True:
            due = [(first, i) for i, hook in enumerate(self.hooks)
                   if (first := hook.due_in(self.driver.iterations, iters)) is not None]
            if not due:
                return self._iterate(iters)
            first, i = min(due)
            reason = self._iterate(first)
            if reason:
                return reason
            with held_interrupt():          # a hook's change (weights, penalties) is made whole or not at all
                self.hooks[i].act(self.problem, self.driver)
            iters -= first

    def _iterate(self, iters: int) -> str | None:
        return self.driver.run(self.problem, iters, self.should_stop)

    # ---- carrying out the policy's actions -----------------------------------------------------------
    def _enter_subspace(self):
        action = on_entry(self._read(), self.rank, self.spaces.n_bands)
        if isinstance(action, Stay):
            self.driver.note(subspace_line(self.spaces.n_bands, self.spaces.n_bands, 0, 1.0, action.why))
        else:
            self._enter(action)

    def _enter(self, action: Enter):
        """The iterates onto the basis (c = Bᵀx), said in the skip report; the first checkpoint in the subspace sets
        the best iterate (see :meth:`_move`)."""
        self.core = action.core
        sub = self.spaces.subspace(action.basis)
        self._count_power(sub)
        self.driver.move(sub.subspace.project, self._step(sub.subspace.lipschitz), sub.objective, evaluate=False)
        self.problem = sub
        self.driver.note(subspace_line(action.basis.shape[1], self.spaces.n_bands, self.driver.iterations + 1,
                                       action.captured, action.how))

    def _check_width(self):
        """One full proximal-gradient step from v = B·c, and the policy's Move or Leave."""
        problem = self.problem
        step = self.driver.step * self.lipschitz / self.spaces.lipschitz      # the full space's step
        judged = not self.rank                     # a fixed rank's check reads only the stepped spectra
        gain, before, stepped = self.spaces.full_step(problem, self.driver.x, step, judged)
        self.driver.work(self.spaces.full_step_transforms(problem, judged))
        action = on_check(before, stepped, gain, problem.subspace.basis, self.core, self.rank, self.spaces.n_bands)
        self.core = action.core
        if isinstance(action, Leave):
            return self._leave(problem, gain)
        if action.widened:
            self._note(f"subspace widened to {action.basis.shape[1]} at iteration {self.driver.iterations + 1}", gain)
        self._move(problem, action)

    def _move(self, problem: Problem, action: Move):
        """The iterates onto another basis, c ↦ B'ᵀB·c (lossless when span(B') ⊇ span(B)), momentum kept.

        The mapped point does not become the best iterate: the subspace's iteration c⁺ = Bᵀ·prox(B·c − s∇) is not a
        proximal-gradient step on F(c) = f(Bc) + g(Bc) (its prox also clips B·c at zero, which F does not charge), so
        a projection can score an F the iteration never reaches again, and a checkpoint held to it rolls back for
        ever (the 96×128 target entered at iteration 91 with 32 vectors: PSNR frozen from iteration 100;
        ``tests/test_skips.py::test_a_late_entry_keeps_improving``). The first checkpoint in the new space sets the
        best."""
        moved, mapping = self.spaces.onto(problem, action.basis)
        self._count_power(moved)
        self.driver.move(mapping, self._step(moved.subspace.lipschitz), moved.objective, evaluate=False)
        if action.basis.shape[1] == problem.rank:
            self._refreshes += 1
        self.problem = moved

    def _leave(self, problem: Problem, gain: float):
        """Back to band space (v = B·c exactly), momentum kept."""
        band = self.spaces.band
        self.driver.move(self.spaces.to_band(problem), self._step(self.spaces.lipschitz), band.objective)
        self.problem = band
        self._note(f"subspace left for band space at iteration {self.driver.iterations + 1}", gain)

    def _count_power(self, problem: Problem):
        """The 2-D FFTs of a new subspace's power iteration for L, counted as work done (work the full solver, one
        space with one L, does not do)."""
        self.driver.work(problem.subspace.power_transforms)

    def _step(self, lipschitz: float) -> float:
        """The step for a space of Lipschitz constant L: the driver's current step·L (step_scale, halved by any
        back-offs so far) over L, so back-offs carry across spaces; the space becomes the current one."""
        scale, self.lipschitz = self.driver.step * self.lipschitz, lipschitz
        return scale / lipschitz

    def _note(self, what: str, gain: float):
        self.driver.note(f"{what} (a full step lowered the data term by {100 * gain:.1f}%)")

    # ---- what the result reports and the next solve can carry ---------------------------------------
    def refreshes_line(self) -> str | None:
        """How often the basis was read again at the same rank (for the skip report)."""
        return (f"subspace basis re-read from a full step's spectra {self._refreshes} times at the same rank"
                if self._refreshes else None)

    def basis(self) -> np.ndarray | None:
        """The basis of the space the solve ended in (None: band space)."""
        return None if self.problem.subspace is None else self.problem.subspace.basis

    def step_factor(self) -> float:
        """The final step times the Lipschitz constant of its space (1 unless backed off)."""
        return self.driver.step * self.lipschitz
