"""The solver's phases: band space, then the spectral subspace when the scene's spectra span few dimensions.

1. Band space for ``WARMUP`` iterations (none after a warm start, whose spectra are known).
2. The spectra of the iterate x (eigen-decomposition of its K × K Gram matrix) give the basis:
   the fewest directions holding all but ``START_TAIL`` of x's energy (or ``--rank R``). If that
   is more than K/2 vectors the subspace would not pay, and the solve stays in band space.
   FISTA moves onto the basis (c = Bᵀx) and goes on with A·B (4r FFTs per iteration).
3. Every ``CHECK_EVERY`` iterations, one full-space proximal-gradient step from v = B·c,
   x⁺ = prox(v − ∇f(v)/L), says whether the basis is right (with ``--rank R`` only the second
   answer applies: r stays R):
   - when it lowers the data term ½‖Av − b‖² by more than ``WIDEN_GAIN`` (relative), the
     measurement holds spectral content the basis cannot represent: the basis grows by the
     leading spectral directions of x⁺'s part outside it (doubling r), losslessly (FISTA keeps its
     iterates and momentum); when r would pass K/2 the solve returns to band space;
   - otherwise the rank is enough but the basis, taken from an early iterate, holds its spectra
     only approximately (blurred lines, say): it is re-estimated from x⁺'s spectra at the same
     rank, and the iterates are projected onto it (momentum kept). The full step sharpens the
     spectra a little each time, so the subspace follows the full problem instead of freezing an
     early guess (on the LED grid, 500 iterations: 42.8 dB against 40.6 dB without).

Every phase, check and widening is counted in the history (``rank``, ``transforms``) and the
skip report.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from .geometry import centred_geometry
from .interrupts import held_interrupt
from .problem import Problem
from .skips import SkipReport, subspace_line
from .subspace import Spectra, SpectralSubspace

WARMUP = 10
CHECK_EVERY = 25
START_TAIL = 5e-2
WIDEN_GAIN = 1e-2
MAX_RANK_FRACTION = 0.5


def in_data_units(record: dict, scale: float) -> dict:
    """A copy of a FISTA record (solver units, b / max|b|) with the data term and objective in data units (×s²)."""
    return {**record, "data": record["data"] * scale ** 2, "objective": record["objective"] * scale ** 2}


class Tracker:
    """Per-iteration bookkeeping: data units, rank and FFTs of each iteration, snapshots, progress, FFT work."""

    def __init__(self, model, scale: float, snapshots=(), progress: Callable[[dict], None] | None = None):
        self.model = model
        self.scale = scale
        self.snapshots = set(snapshots)
        self.progress = progress
        self.kept: dict[int, np.ndarray] = {}
        self.report = SkipReport()
        self.voxels = model.geometry.voxels_per_band
        self.paper_voxels = centred_geometry(model.sensor_shape).voxels_per_band
        self.full_transforms = 4 * model.n_bands        # the full solver's gradient step

    def on(self, problem: Problem):
        """FISTA's on_iteration callback for iterations in ``problem``'s space: adds the rank and transforms to
        the record (its numbers stay in solver units: FISTA's rules compare them); progress gets data units."""
        def on_iteration(record: dict, x):
            evaluated = math.isfinite(record["objective"])
            transforms = problem.transforms() * (3 if evaluated else 2) // 2     # + a forward for F(x)
            record["rank"] = problem.rank
            record["transforms"] = transforms
            self.count(transforms, self.full_transforms * (3 if evaluated else 2) // 2)
            if record["iteration"] in self.snapshots:
                self.kept[record["iteration"]] = (self.model.window(problem.solution(x)) * self.scale).astype(np.float32)
            if self.progress is not None:
                self.progress(in_data_units(record, self.scale))
        return on_iteration

    def count(self, transforms: int, full_transforms: int = 0):
        """Add FFT work done (at this field) and the full solver's (at the paper's field)."""
        self.report.done_work += transforms * self.voxels
        self.report.full_work += full_transforms * self.paper_voxels


class Phases:
    """Runs one solve's FISTA loop through its spaces (see the module docstring)."""

    def __init__(self, solver, loop, tracker: Tracker, priors: list):
        self.solver = solver
        self.settings = solver.settings
        self.backend = solver.backend
        self.loop = loop
        self.tracker = tracker
        self.priors = priors
        self.n_bands = solver.model.n_bands
        self.problem: Problem | None = None         # the space FISTA's iterates are in
        self._full: Problem | None = None
        self._buffers: dict = {}
        self._lipschitz = solver.lipschitz          # of the space the loop is in
        self._refreshes = 0                         # bases re-estimated at the same rank

    def run(self, problem: Problem, warm_started: bool) -> tuple[str, Problem]:
        """(stop reason, the problem the final iterate lives in)."""
        self.problem = problem
        try:
            return self._run_phases(warm_started), self.problem
        except KeyboardInterrupt:     # between FISTA runs; moves between spaces finish first (held_interrupt)
            return "interrupted", self.problem

    def _run_phases(self, warm_started: bool) -> str:
        iters, loop = self.settings.iters, self.loop
        if self._subspace_allowed():
            reason = self._run(self.problem, 0 if warm_started else min(WARMUP, iters))
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

    def refreshes_line(self) -> str | None:
        """How often the basis was re-estimated at the same rank (for the skip report)."""
        return (f"subspace basis re-estimated from a full step {self._refreshes} times at the same rank"
                if self._refreshes else None)

    def _run(self, problem: Problem, iters: int) -> str | None:
        return self.loop.run(problem.gradient_step, problem.prox, iters, self.tracker.on(problem))

    def _subspace_allowed(self) -> bool:
        s = self.settings
        if not s.skip:
            return False
        if s.rank:
            return s.rank < self.n_bands
        return self.n_bands * MAX_RANK_FRACTION >= 2      # fewer bands: r ≤ K/2 saves too little

    # ---- entering the subspace --------------------------------------------------------------
    def _enter_subspace(self, problem: Problem) -> Problem:
        spectra = Spectra.of(self.backend, self.loop.x)
        rank = self.settings.rank or self._automatic_rank(spectra)
        report = self.tracker.report
        if rank > self.n_bands * MAX_RANK_FRACTION and not self.settings.rank:
            report.lines.append(subspace_line(self.n_bands, self.n_bands, 0, 1.0,
                                              f"{rank} directions hold the spectra: band space is cheaper"))
            return problem
        subspace = self._subspace_problem(spectra.basis(rank))
        self.loop.change_space(subspace.subspace.project, self._step(subspace.subspace.lipschitz), subspace.objective)
        how = f"--rank {rank}" if self.settings.rank else f"all but {START_TAIL:g} of the energy"
        report.lines.append(subspace_line(rank, self.n_bands, self.loop.iterations + 1, spectra.captured(rank), how))
        return subspace

    @staticmethod
    def _automatic_rank(spectra: Spectra) -> int:
        """The fewest directions holding all but START_TAIL of the iterate's energy."""
        total = spectra.energies.sum()
        if total <= 0:
            return 1
        held = np.cumsum(spectra.energies) / total
        return int(np.searchsorted(held, 1.0 - START_TAIL) + 1)

    def _subspace_problem(self, basis: np.ndarray, start=None) -> Problem:
        sub = SpectralSubspace(self.solver.model, basis, self.priors, self.solver.calibration.filters, start)
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
        """One full proximal-gradient step from v = B·c: widen the basis, or re-estimate it at the same rank."""
        sub, be = problem.subspace, self.backend
        full = self._full_problem()
        data = problem.data(self.loop.x)                         # its residual A·B·c − b = A·v − b stays in place
        step = self._full_step()
        gradient_step = full.model.adjoint(problem.residual_buffer, out=self._cube("z"), y=sub.expand(self.loop.x),
                                           step=step)            # z = v − step·Aᵀ(Av − b)
        stepped = full.prox(gradient_step, self._cube("stepped"), step)
        gain = (data - full.data(stepped)) / data if data > 0 else 0.0
        self.tracker.count(problem.transforms() // 2 + full.transforms())      # A·B·c, then Aᵀr and A·x⁺
        if gain <= WIDEN_GAIN or self.settings.rank:
            return self._move(sub, Spectra.of(be, stepped).basis(sub.rank))     # same rank, better spectra
        rank = min(2 * sub.rank, self.n_bands)
        if rank > self.n_bands * MAX_RANK_FRACTION:
            return self._leave_subspace(problem, gain)
        outside = be.axpy(-1.0, sub.expand(sub.project(stepped)), stepped, out=self._cube("z"))   # x⁺ − BBᵀx⁺
        basis, _ = np.linalg.qr(np.hstack([sub.basis, Spectra.of(be, outside).basis(rank - sub.rank)]))
        self._note(f"subspace widened to {rank} at iteration {self.loop.iterations + 1}", gain)
        return self._move(sub, basis)

    def _move(self, subspace: SpectralSubspace, basis: np.ndarray) -> Problem:
        """FISTA onto another basis, c ↦ B'ᵀB·c (lossless when span(B') ⊇ span(B)), momentum kept."""
        mix = basis.T @ subspace.basis
        moved = self._subspace_problem(basis, start=self.backend.bandmix(subspace.model.power_vector, mix))
        self.loop.change_space(lambda c: self.backend.bandmix(c, mix), self._step(moved.subspace.lipschitz),
                               moved.objective)
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
