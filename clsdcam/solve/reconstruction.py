"""One solve: a :class:`Reconstruction` is built from a :class:`~clsdcam.solve.solver.Solver` (one calibration on one
backend) and one measurement, and owns everything that lives for that solve alone (SigPy's ``App``):

* b / s on the device, with s = max|b|, and the solve's :class:`~clsdcam.solve.units.Units` (every conversion between
  solver and data units, for the cube, its snapshots, the history and the carried state);
* its start (:mod:`clsdcam.solve.state`), priors, spaces (:mod:`clsdcam.solve.spaces`), algorithm, driver, the
  driver's observers (:mod:`clsdcam.solve.tracker`: ranks, FFT work and the skip report, snapshots, progress) and
  phases;
* the :class:`~clsdcam.solve.result.Result` it hands back.

The solver keeps only what serves every solve of its calibration: the model, its Lipschitz constant, the last
subspace's L and the shared store algorithms build their calibration terms in.
"""
from __future__ import annotations

import math
from functools import cached_property
from typing import Callable

import numpy as np

from .. import __version__
from ..algorithms import ALGORITHMS
from .auto_weights import AutoWeights
from .driver import Driver, Rules
from ..errors import InputError, shape_text
from .noise import residual_noise
from .phases import Phases
from .priors import PRIORS, build_priors, singular_values
from .problem import Problem
from .result import Result
from .skips import SkipReport, bands_line, field_line, terms_line
from .spaces import Spaces
from .state import SolverState, Start
from .tracker import Progress, Ranks, Snapshots, Work
from .units import Units


class Reconstruction:
    """One measurement on one solver (the module docstring); :meth:`run` solves it once."""

    def __init__(self, solver, measurement: np.ndarray, x0=None, state: SolverState | None = None):
        """``x0``: a warm start in data units, a (K, H, W) cube or a whole field; ``state``: a previous
        ``Result.state`` of this solver, whose field, basis, step, weights and carry it starts from instead."""
        self.solver = solver
        self.model, self.backend, self.settings = solver.model, solver.backend, solver.settings
        b = solver.checked(measurement)
        scale = float(np.max(np.abs(b)))          # s; a zero measurement keeps s = 1 (nothing to solve)
        self.units = Units(scale or 1.0, solver.calibration.scale)
        self.b = self.backend.to_device(b / scale) if scale else None
        self._x0, self._state = x0, state

    def run(self, progress: Callable[[dict], None] | None = None, snapshots=(), iters: int | None = None,
            stop_at_fit: float | None = None) -> Result:
        """The result (see :meth:`clsdcam.solve.solver.Solver.solve` for the arguments)."""
        if self.b is None:
            return self._result(self.model.zero_field(), [], "zero measurement")
        be, s, solver = self.backend, self.settings, self.solver
        start = self._state.start(be, self.units.solver_factor) if self._state else self.start()
        priors = build_priors(be, s, start.reference(DataReferences(self.model, self.b, solver.lipschitz).value))
        start.apply_weights(priors)
        spaces = Spaces(self.model, self.b, priors, solver.calibration.filters, solver.lipschitz,
                        solver.last_lipschitz, solver.shared)
        rules = Rules(converge=s.stop_distance, tol=s.tol, plateau=s.plateau, objective_every=s.objective_every,
                      restart=s.restart)
        algorithm = ALGORITHMS[s.algorithm](be, start.field, start.step_factor / solver.lipschitz, rules)
        if start.carry is not None:
            algorithm.resume(*start.carry)
        work, copies = Work(self.model), Snapshots(self.model, self.units, snapshots)
        observers = [Ranks(), work, copies] + ([Progress(self.units, progress)] if progress is not None else [])
        # a carried basis is entered at once: no band-space F(x0)
        driver = Driver(algorithm, rules, None if start.basis is not None else spaces.band.objective, observers)
        off = [row.name for row in PRIORS if row.name not in {p.name for p in priors}]
        driver.note(field_line(solver.geometry), self._bands_line(), terms_line(off))
        weights = AutoWeights(priors, algorithm.point_like_below, s.wide_stop, algorithm.widely_lit_above)
        phases = Phases(driver, spaces, s, iters or s.budget, (weights,), self._fit_rule(driver, stop_at_fit))
        reason = phases.run(start.warm, start.basis, start.core)
        weights.unchosen(driver)
        driver.note(phases.refreshes_line())
        field = phases.problem.solution(driver.x)
        out = self._result(field, driver.history, reason, priors, driver.step, work.report)
        out.attrs.update({f"{p.name}_chosen": p.relative for p in priors}, **weights.chosen)
        fit, structure = self._residual_figures(phases.problem, driver.x)
        out.attrs.update(relative_residual=fit, residual_to_noise=structure)
        if rules.converge:
            out.attrs["distance_estimate"] = driver.history[-1]["distance"] if driver.history else math.inf
            out.attrs["stop_tolerance"] = driver.rules.converge
        out.snapshots = copies.kept
        carry = algorithm.carry()
        factor = self.units.cube_factor
        out.state = SolverState(be.scale(factor, field), phases.basis(), phases.core, phases.step_factor(),
                                {p.name: p.relative for p in priors}, fit, {p.reference: p.unit for p in priors},
                                None if carry is None else (carry, factor))
        return out

    def _fit_rule(self, driver: Driver, fit: float | None):
        """The driver's should_stop for ``stop_at_fit``: "fit" once the record's data term ½‖Ay − b‖² is at most
        ½ fit²·‖b‖² (None: no such rule)."""
        if not fit:
            return None
        target = 0.5 * fit ** 2 * self.backend.vdot(self.b, self.b)
        return lambda: "fit" if driver.history and driver.history[-1]["data"] <= target else None

    def _residual_figures(self, problem: Problem, x) -> tuple[float, float]:
        """(‖r‖/‖b‖, rms(r)/σ̂(r)) of the final residual r = Av − b: how much of the measurement the cube leaves
        unexplained, and whether that is noise (rms over the noise level read from r's finest wavelet details,
        :func:`clsdcam.solve.noise.residual_noise`: 1.0–4.0 on the simulator's six panel scenes, 8.6–18.8 with a
        calibration of the right size but another camera's, 60 iterations, 64×96×16; the bright sparse scenes,
        point sources and narrow lines, leave the most unfitted structure)."""
        problem.residual(x)
        r = self.backend.to_host(problem.residual_buffer)
        norm = float(np.sqrt(self.backend.vdot(self.b, self.b)))
        sigma = residual_noise(r)
        rms = float(np.sqrt(np.mean(np.square(r, dtype=np.float64))))
        return (float(np.linalg.norm(r)) / norm if norm > 0 else 0.0), (rms / sigma if sigma > 0 else 0.0)

    def _bands_line(self):
        return bands_line(self.solver.calibration.filters) if self.settings.skip else None

    def start(self) -> Start:
        """Where this solve starts without a state: zero, the warm start x0 as a (K, H, W) sensor-window cube (zero
        around it), or x0 as a whole field, in solver units."""
        return Start(self._first_iterate(), self.settings.step_scale, warm=self._x0 is not None)

    def _first_iterate(self):
        if self._x0 is None:
            return self.model.zero_field()
        x0 = self.units.to_solver(self._x0)
        if x0.shape == self.model.cube_shape:
            return self.backend.to_device(x0)
        if x0.shape != self._window_shape():
            raise InputError(f"warm start {shape_text(x0.shape)}: expected {shape_text(self._window_shape())} "
                             f"or the field {shape_text(self.model.cube_shape)}")
        return self.model.embed(x0)

    def _window_shape(self):
        return (self.model.n_bands,) + self.model.sensor_shape

    def _result(self, x, history, reason, priors: list | None = None, step: float = 0.0,
                report: SkipReport | None = None) -> Result:
        solver, model, units = self.solver, self.model, self.units
        cube = units.cube(model.window(x))
        full = units.cube(self.backend.to_host(x)) if self.settings.full_field else None
        history = [units.record(record) for record in history]
        attrs = {
            **solver.settings_attrs(),
            "iterations": len(history),
            "stop_reason": reason,
            "lipschitz": solver.lipschitz,
            "final_step": step,
            **{f"{key}s": sum(bool(r.get(key)) for r in history)     # restart: FISTA's own key (0 for others)
               for key in ("restart", "rollback", "backoff")},
            "data_scale": units.measurement,
            "field_shape": model.field_shape,
            "window_offset": model.offset,
            "active_priors": ",".join(p.name for p in priors or ()),
            "skips": report.summary() if report else "",
            "fft_work_saved": report.saved if report else 0.0,
            "final_rank": history[-1]["rank"] if history else model.n_bands,
            "clsdcam_version": __version__,
            "calibration": solver.calibration.source,
            "calibration_scale": solver.calibration.scale,
        }
        return Result(cube=cube, wavelengths=np.asarray(solver.calibration.wavelengths), history=history,
                      attrs=attrs, full_field=full)


class DataReferences:
    """What a relative prior weight of 1 means for a (normalised) measurement b on the device, each computed on
    first use: ``atb_max`` = ‖Aᵀb‖_∞, ``atb_sigma1`` = σ₁(Aᵀb), ``lipschitz`` = L
    (see :mod:`clsdcam.solve.priors`)."""

    def __init__(self, model, b, lipschitz: float):
        self.model, self.b, self.lipschitz = model, b, lipschitz

    def value(self, name: str) -> float:
        return float(getattr(self, name))

    @cached_property
    def atb(self):
        return self.model.adjoint(self.b)

    @cached_property
    def atb_max(self) -> float:
        return self.model.backend.amax(self.atb)

    @cached_property
    def atb_sigma1(self) -> float:
        return float(singular_values(self.model.backend, self.atb).max())
