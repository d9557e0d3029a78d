"""Reconstruction: one measurement + a calibration -> a hyperspectral cube.

    argmin_{v ≥ 0} ½‖b − Av‖² + Σ_i τ_i·φ_i(v)     by an algorithm of :mod:`clsdcam.algorithms` (FISTA), step 1/L

with the priors φ_i of :mod:`clsdcam.priors` (TV by default). The solver builds the model once per calibration;
each solve builds its start (:mod:`clsdcam.state`), priors, spaces (:mod:`clsdcam.spaces`) and algorithm, and
hands them to the phases (:mod:`clsdcam.phases`), which run the driver (:mod:`clsdcam.driver`).

Units. The measurement is used as given. Internally it is divided by s = max|b| (the solver's
units: the driver's records, objective and checkpoints are all in them); the result's cube and history
are turned back into data units here, at the edge. The user's weights are relative to the data
(each prior's reference, see :mod:`clsdcam.priors`), so scaling the measurement by s scales the
cube by s, and the same weights suit any PSF or filter normalisation.

Skips (``skip=True``, the default; ``skip=False`` is the full solver: the paper's field, every
band, every iteration in band space): no FFTs for bands no filter sees, pruned transforms on the host
path, zero-weight terms never evaluated: all exact, so the default solves ``--no-skip``'s
problem on its field. Two speed options change the problem and are taken only when asked: the spectral
subspace (``subspace=True`` or ``rank``, see :mod:`clsdcam.space_policy`) and the support-sized field
(``support_field=True``, see :mod:`clsdcam.skips`); docs/accuracy.md says why neither is the default.
Each is reported in ``Result.attrs["skips"]`` with the FFT work it saved.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field
from functools import cached_property
from typing import Callable

import numpy as np

from . import __version__
from .backends import get_backend
from .errors import InputError, shape_text
from .algorithms import ALGORITHMS
from .auto_weights import AutoWeights
from .driver import Driver, Rules
from .io import require_finite
from .noise import residual_noise
from .model import ForwardModel
from .phases import Phases
from .tracker import Tracker, in_data_units
from .priors import PRIORS, build_priors, singular_values
from .problem import Problem
from .settings import Settings
from .skips import bands_line, field_line, plan_geometry, terms_line
from .spaces import LastLipschitz, Spaces
from .splitting import CalibrationTerms
from .state import SolverState, Start

__all__ = ["Result", "Settings", "Solver", "reconstruct"]


@dataclass
class Result:
    cube: np.ndarray               # (K, H, W) float32, the sensor window
    wavelengths: np.ndarray        # (K,)
    history: list[dict]
    attrs: dict
    full_field: np.ndarray | None = None
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)  # iteration -> (K, H, W) cube
    state: SolverState | None = None     # what the next frame of a stream can start from (clsdcam.state)

    @property
    def iterations(self) -> int:
        return int(self.attrs["iterations"])

    @property
    def stop_reason(self) -> str:
        return str(self.attrs["stop_reason"])

    def save(self, path):
        """Write the cube, wavelengths, history and attributes to HDF5, atomically."""
        from .io import write_cube

        write_cube(path, self.cube, self.wavelengths, self.history, self.attrs, full_field=self.full_field)


class Solver:
    """One calibration on one backend: the model, its Lipschitz constant and buffers, built once."""

    def __init__(self, calibration, backend="numpy", device: str | None = None, settings: Settings | None = None,
                 fft: str = "auto", path: str = "auto"):
        self.settings = settings or Settings()
        self.backend = get_backend(backend, self.settings.dtype, device, fft, path) if isinstance(backend, str) \
            else backend
        self.calibration = calibration
        support = self.settings.skip and self.settings.support_field
        self.geometry = plan_geometry(calibration.psf, self.backend, support)
        self._check_memory()
        self.model = ForwardModel(self.backend, calibration.psf, calibration.filters, geometry=self.geometry,
                                  skip_unseen=self.settings.skip)
        self.lipschitz = self.model.lipschitz()
        self.b = None          # the measurement being solved, divided by max|b|, on the device
        self.last_lipschitz = LastLipschitz()    # L of the last spectral subspace: reused for the same basis
        self._splitting_terms = None              # ADMM's terms of this calibration, built on first use

    def solve(self, measurement: np.ndarray, x0: np.ndarray | None = None,
              progress: Callable[[dict], None] | None = None, snapshots=(), state: SolverState | None = None,
              iters: int | None = None, stop_at_fit: float | None = None) -> Result:
        """Reconstruct one (H, W) measurement.

        x0 is an optional warm start in data units: a (K, H, W) cube or a whole field (``Result.full_field``);
        ``state`` (a previous ``Result.state`` of this solver, e.g. the last frame of a video) starts from its
        field instead and carries its basis, rank, step and weights (:mod:`clsdcam.state`); ``snapshots`` lists
        iterations at which a copy of the cube is kept in ``Result.snapshots`` (e.g. to measure accuracy);
        ``iters`` overrides ``Settings.iters`` for this solve (a stream's cold and warm frames); ``stop_at_fit``
        stops it (reason "fit") once ‖Ay − b‖/‖b‖ at the algorithm's gradient point is at most that (e.g. the
        previous frame's fit: a frame that changed little stops early, one that changed more gets the iterations).
        """
        b = self._checked(measurement)
        scale = float(np.max(np.abs(b)))
        if scale == 0.0:
            return self._result(self.model.embed(np.zeros(self._cube_window_shape())), 1.0, [], "zero measurement")
        be, s = self.backend, self.settings
        self.b = be.to_device(b / scale)
        start = state.start(be, self.calibration.scale / scale) if state else self._start(x0, scale)
        priors = build_priors(be, s, start.reference(DataReferences(self.model, self.b, self.lipschitz).value))
        start.apply_weights(priors)
        spaces = Spaces(self.model, self.b, priors, self.calibration.filters, self.lipschitz, self.last_lipschitz,
                        self.splitting_terms)
        rules = Rules(tol=s.tol, plateau=s.plateau, objective_every=s.objective_every, restart=s.restart)
        algorithm = ALGORITHMS[s.algorithm](be, start.field, start.step_factor / self.lipschitz, rules)
        if start.carry is not None and hasattr(algorithm, "resume"):
            algorithm.resume(*start.carry)
        # a carried basis is entered at once: no band-space F(x0)
        driver = Driver(algorithm, rules, None if start.basis is not None else spaces.band.objective)
        tracker = Tracker(self.model, scale, snapshots, progress)
        off = [row.name for row in PRIORS if row.name not in {p.name for p in priors}]
        tracker.report.lines += [line for line in (field_line(self.geometry), self._bands_line(), terms_line(off))
                                 if line]
        weights = AutoWeights(priors, tracker.report.lines)
        phases = Phases(driver, spaces, tracker, s, iters or s.iters, (weights,), self._fit_rule(driver, stop_at_fit))
        reason = phases.run(start.warm, start.basis, start.core)
        tracker.report.lines += [line for line in (phases.refreshes_line(),) if line]
        field = phases.problem.solution(driver.x)
        out = self._result(field, scale, driver.history, reason, priors, driver.step, tracker)
        out.attrs.update({f"{p.name}_chosen": p.relative for p in priors}, **weights.chosen)
        fit, structure = self._residual_figures(phases.problem, driver.x)
        out.attrs.update(relative_residual=fit, residual_to_noise=structure)
        out.snapshots = tracker.kept
        carry = algorithm.carry() if hasattr(algorithm, "carry") else None
        out.state = SolverState(be.scale(scale / self.calibration.scale, field), phases.basis(), phases.core,
                                phases.step_factor(), {p.name: p.relative for p in priors}, fit,
                                {p.reference: p.unit for p in priors},
                                None if carry is None else (carry, scale / self.calibration.scale))
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
        :func:`clsdcam.noise.residual_noise`: 1.0–4.0 on the simulator's six panel scenes, 8.6–18.8 with a
        calibration of the right size but another camera's, 60 iterations, 64×96×16; the bright sparse scenes,
        point sources and narrow lines, leave the most unfitted structure)."""
        problem.residual(x)
        r = self.backend.to_host(problem.residual_buffer)
        norm = float(np.sqrt(self.backend.vdot(self.b, self.b)))
        sigma = residual_noise(r)
        rms = float(np.sqrt(np.mean(np.square(r, dtype=np.float64))))
        return (float(np.linalg.norm(r)) / norm if norm > 0 else 0.0), (rms / sigma if sigma > 0 else 0.0)

    # ---- pieces -------------------------------------------------------------------------
    def splitting_terms(self) -> CalibrationTerms:
        """ADMM's :class:`~clsdcam.splitting.CalibrationTerms` of this solver's model, built once."""
        if self._splitting_terms is None:
            self._splitting_terms = CalibrationTerms(self.model, self.calibration.filters)
        return self._splitting_terms

    def _check_memory(self):
        """Devices with their own memory say up front (InputError) when the problem cannot fit."""
        check = getattr(self.backend, "check_problem", None)
        if check is not None:
            cubes = getattr(ALGORITHMS[self.settings.algorithm], "field_buffers", None)
            check(self.geometry.sensor, self.geometry.field, self.calibration.filters.shape[0], field_buffers=cubes)

    def _bands_line(self):
        return bands_line(self.calibration.filters) if self.settings.skip else None

    def _start(self, x0, scale: float) -> Start:
        """A start without a state: zero, a (K, H, W) sensor-window cube (zero around it), or a whole field."""
        return Start(self._first_iterate(x0, scale), self.settings.step_scale, warm=x0 is not None)

    def _first_iterate(self, x0, scale: float):
        if x0 is None:
            return self.model.embed(np.zeros(self._cube_window_shape()))
        x0 = np.asarray(x0) * self.calibration.scale / scale
        if x0.shape == self.model.cube_shape:
            return self.backend.to_device(x0)
        if x0.shape != self._cube_window_shape():
            raise InputError(f"warm start {shape_text(x0.shape)}: expected {shape_text(self._cube_window_shape())} "
                             f"or the field {shape_text(self.model.cube_shape)}")
        return self.model.embed(x0)

    def _cube_window_shape(self):
        return (self.model.n_bands,) + self.model.sensor_shape

    def _checked(self, measurement) -> np.ndarray:
        b = np.asarray(measurement, dtype=np.float64)
        if b.shape != self.model.sensor_shape:
            raise InputError(f"measurement {shape_text(b.shape)} does not match calibration {shape_text(self.model.sensor_shape)}")
        return require_finite(b, "measurement")

    def _result(self, x, scale, history, reason, priors: list | None = None, step: float = 0.0,
                tracker: Tracker | None = None) -> Result:
        model, units = self.model, scale / self.calibration.scale      # solver units -> the calibration's units
        cube = (model.window(x) * units).astype(np.float32)
        full = (self.backend.to_host(x) * units).astype(np.float32) if self.settings.full_field else None
        history = [in_data_units(record, scale) for record in history]
        attrs = {
            **{k: v for k, v in asdict(self.settings).items()},
            "backend": self.backend.name,
            "device": self.backend.device_name,
            "path": self.backend.path,
            "fft_engine": self.backend.fft_engine,
            "iterations": len(history),
            "stop_reason": reason,
            "lipschitz": self.lipschitz,
            "final_step": step,
            **{f"{key}s": sum(bool(r.get(key)) for r in history)     # restart: FISTA's own key (0 for others)
               for key in ("restart", "rollback", "backoff")},
            "data_scale": scale,
            "field_shape": model.field_shape,
            "window_offset": model.offset,
            "active_priors": ",".join(p.name for p in priors or ()),
            "skips": tracker.report.summary() if tracker else "",
            "fft_work_saved": tracker.report.saved if tracker else 0.0,
            "final_rank": history[-1]["rank"] if history else model.n_bands,
            "clsdcam_version": __version__,
            "calibration": self.calibration.source,
            "calibration_scale": self.calibration.scale,
        }
        return Result(cube=cube, wavelengths=np.asarray(self.calibration.wavelengths), history=history,
                      attrs=attrs, full_field=full)


class DataReferences:
    """What a relative prior weight of 1 means for a (normalised) measurement b on the device, each computed on
    first use: ``atb_max`` = ‖Aᵀb‖_∞, ``atb_sigma1`` = σ₁(Aᵀb), ``lipschitz`` = L (see :mod:`clsdcam.priors`)."""

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


def reconstruct(measurement, calibration, backend="numpy", device: str | None = None, x0=None,
                progress: Callable[[dict], None] | None = None, fft: str = "auto", path: str = "auto",
                preprocessing=None, **settings) -> Result:
    """Reconstruct a cube from one measurement (an array or an image/.npy/.h5 path) with a calibration (a
    :class:`~clsdcam.calibration.Calibration` or a file path), preprocessed as the command line does
    (``preprocessing``: a :class:`~clsdcam.calibration.Preprocessing`, default its defaults); the cube comes
    back in the calibration's units. ``settings`` are the fields of ``Settings``. ``backend`` (also
    :class:`Solver`'s): ``"numpy"`` by default, the reference, the same result on every machine; ``"opencl"``; or
    ``"auto"``, the command line's default (:func:`clsdcam.backends.resolve_backend`: OpenCL on a GPU when one is
    found, else NumPy)."""
    from .calibration import prepare

    calibration, measurement = prepare(measurement, calibration, preprocessing)
    solver = Solver(calibration, backend=backend, device=device, settings=Settings(**settings), fft=fft, path=path)
    return solver.solve(measurement, x0=x0, progress=progress)
