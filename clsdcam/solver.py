"""Reconstruction: one measurement + a calibration -> a hyperspectral cube.

    argmin_{v ≥ 0} ½‖b − Av‖² + τ₁·TV_w(v) + τ₂·‖V‖_* + τ₃·‖v‖₁     by FISTA with step 1/L.

Units. The measurement is used as given. Internally it is divided by s = max|b|, and the
user's weights are relative: τ₁ and τ₃ are fractions of ‖Aᵀb‖_∞ (the weight above which
an L1 prior would zero the cube), τ₂ a fraction of σ₁(Aᵀb), the largest singular value of
the pixels×bands unfolding of Aᵀb. So scaling the measurement by s scales the cube by s,
and the same weights suit any PSF or filter normalisation.

Skips (``skip=True``, the default; ``skip=False`` is the full solver: the paper's field, every
band, every iteration in band space): the support-sized field, no FFTs for bands no filter
sees, zero-weight terms never evaluated, and the spectral subspace (see :mod:`clsdcam.phases`).
Each is reported in ``Result.attrs["skips"]`` with the FFT work it saved.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from . import __version__
from .backends import get_backend
from .errors import InputError, shape_text
from .io import require_finite
from .fista import Fista, Rules
from .model import ForwardModel
from .phases import Phases, Tracker
from .priors import Prox, Regularizer, singular_values
from .problem import Problem
from .skips import bands_line, field_line, plan_geometry, terms_line

DEFAULT_ITERS = 300
DEFAULT_TV = 1e-3  # tuned on the simulated target and LED scenes (README, "Choosing --tv")
DEFAULT_TOL = 0.0


@dataclass(frozen=True)
class Settings:
    """Solver settings; weights are relative to the data (see the module docstring)."""

    iters: int = DEFAULT_ITERS
    tv: float = DEFAULT_TV
    tv_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)  # x, y, λ
    lowrank: float = 0.0
    l1: float = 0.0
    tol: float = DEFAULT_TOL
    plateau: float = 0.0           # stop when F fell by less than this (relative) between checkpoints
    skip: bool = True              # skip what the scene doesn't need (False: the full solver)
    rank: int = 0                  # spectral basis vectors: 0 = automatic, ≥ K = no subspace
    dtype: str = "float32"
    objective_every: int = 10      # F(x) evaluated (and the best iterate kept) this often
    restart: bool = True           # adaptive momentum restart (O'Donoghue–Candès)
    step_scale: float = 1.0        # step = step_scale / L; > 1 only to test the back-off
    full_field: bool = False

    def __post_init__(self):
        object.__setattr__(self, "tv_weights", tuple(float(w) for w in self.tv_weights))
        _require(isinstance(self.iters, (int, np.integer)) and self.iters >= 1, f"--iters {self.iters}: must be an integer ≥ 1")
        _require(_finite_nonneg(self.step_scale) and self.step_scale > 0, f"step_scale {self.step_scale}: must be > 0")
        _require(isinstance(self.rank, (int, np.integer)) and self.rank >= 0, f"--rank {self.rank}: must be an integer ≥ 0")
        for name in ("tv", "lowrank", "l1", "tol", "plateau"):
            value = getattr(self, name)
            _require(_finite_nonneg(value), f"--{name} {value}: must be a finite number ≥ 0")
        _require(len(self.tv_weights) == 3 and all(_finite_nonneg(w) for w in self.tv_weights),
                 f"--tv-weights {self.tv_weights}: expected three finite numbers ≥ 0 (x, y, λ)")
        _require(self.objective_every >= 1, f"objective_every {self.objective_every}: must be ≥ 1")


def _finite_nonneg(value) -> bool:
    return isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value >= 0


def _require(condition: bool, message: str):
    if not condition:
        raise InputError(message)


@dataclass
class Result:
    cube: np.ndarray               # (K, H, W) float32, the sensor window
    wavelengths: np.ndarray        # (K,)
    history: list[dict]
    attrs: dict
    full_field: np.ndarray | None = None
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)  # iteration -> (K, H, W) cube

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
                 fft: str = "auto"):
        self.settings = settings or Settings()
        self.backend = get_backend(backend, self.settings.dtype, device, fft) if isinstance(backend, str) else backend
        self.calibration = calibration
        self.geometry = plan_geometry(calibration.psf, self.backend, self.settings.skip)
        self._check_memory()
        self.model = ForwardModel(self.backend, calibration.psf, calibration.filters, geometry=self.geometry,
                                  skip_unseen=self.settings.skip)
        self.lipschitz = self.model.lipschitz()
        self.b = None          # the measurement being solved, divided by max|b|, on the device

    def solve(self, measurement: np.ndarray, x0: np.ndarray | None = None,
              progress: Callable[[dict], None] | None = None, snapshots=()) -> Result:
        """Reconstruct one (H, W) measurement.

        x0 is an optional warm start in data units: a (K, H, W) cube or a whole field (``Result.full_field``);
        ``snapshots`` lists iterations at which a copy of the cube is kept in ``Result.snapshots`` (e.g. to
        measure accuracy on the way).
        """
        b = self._checked(measurement)
        scale = float(np.max(np.abs(b)))
        if scale == 0.0:
            return self._result(self.model.embed(np.zeros(self._cube_window_shape())), 1.0, [], "zero measurement")
        be, s = self.backend, self.settings
        self.b = be.to_device(b / scale)
        regularizer = self._regularizer()
        problem = self.band_problem(regularizer)
        loop = Fista(be, self._start(x0, scale), step=s.step_scale / self.lipschitz, objective=problem.objective,
                     rules=Rules(tol=s.tol, plateau=s.plateau, objective_every=s.objective_every, restart=s.restart))
        tracker = Tracker(self.model, scale, snapshots, progress)
        tracker.report.lines += [line for line in (field_line(self.geometry), self._bands_line(),
                                                   terms_line(regularizer.inactive_terms())) if line]
        phases = Phases(self, loop, tracker, regularizer)
        reason, problem = phases.run(problem, warm_started=x0 is not None)
        tracker.report.lines += [line for line in (phases.refreshes_line(),) if line]
        out = self._result(problem.solution(loop.x), scale, loop.history, reason, regularizer, loop.step, tracker)
        out.snapshots = tracker.kept
        return out

    def band_problem(self, regularizer: Regularizer) -> Problem:
        """The problem on the band cube (the full problem)."""
        prox = Prox(self.backend, regularizer, self.model.cube_shape)
        return Problem(self.model, self.b, prox, lambda x: regularizer.value(self.backend, x), self.model.n_bands)

    # ---- pieces -------------------------------------------------------------------------
    def _check_memory(self):
        """Devices with their own memory say up front (InputError) when the problem cannot fit."""
        check = getattr(self.backend, "check_problem", None)
        if check is not None:
            check(self.geometry.sensor, self.geometry.field, self.calibration.filters.shape[0])

    def _bands_line(self):
        return bands_line(self.calibration.filters) if self.settings.skip else None

    def _start(self, x0, scale: float):
        """The first iterate: zero, a (K, H, W) sensor-window cube (zero around it), or a whole field."""
        if x0 is None:
            return self.model.embed(np.zeros(self._cube_window_shape()))
        x0 = np.asarray(x0) / scale
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

    def _regularizer(self) -> Regularizer:
        """Absolute weights: τ₁, τ₃ times ‖Aᵀb‖_∞ and τ₂ times σ₁(Aᵀb), for the normalised b."""
        s, be = self.settings, self.backend
        atb = self.model.adjoint(self.b)
        data_scale = be.amax(atb)
        sigma1 = float(singular_values(be, atb).max()) if s.lowrank > 0 else 0.0
        return Regularizer(tv=s.tv * data_scale, tv_weights=s.tv_weights, lowrank=s.lowrank * sigma1,
                           l1=s.l1 * data_scale)

    def _result(self, x, scale, history, reason, regularizer: Regularizer | None = None, step: float = 0.0,
                tracker: Tracker | None = None) -> Result:
        model = self.model
        cube = (model.window(x) * scale).astype(np.float32)
        full = (self.backend.to_host(x) * scale).astype(np.float32) if self.settings.full_field else None
        attrs = {
            **{k: v for k, v in asdict(self.settings).items()},
            "backend": self.backend.name,
            "device": self.backend.device_name,
            "fft_engine": self.backend.fft_engine,
            "iterations": len(history),
            "stop_reason": reason,
            "lipschitz": self.lipschitz,
            "final_step": step,
            **{f"{key}s": sum(bool(r[key]) for r in history) for key in ("restart", "rollback", "backoff")},
            "data_scale": scale,
            "field_shape": model.field_shape,
            "window_offset": model.offset,
            "active_priors": ",".join(regularizer.active_terms()) if regularizer else "",
            "skips": tracker.report.summary() if tracker else "",
            "fft_work_saved": tracker.report.saved if tracker else 0.0,
            "final_rank": history[-1]["rank"] if history else model.n_bands,
            "clsdcam_version": __version__,
            "calibration": self.calibration.source,
        }
        return Result(cube=cube, wavelengths=np.asarray(self.calibration.wavelengths), history=history,
                      attrs=attrs, full_field=full)


def reconstruct(measurement, calibration, backend="numpy", device: str | None = None, x0=None,
                progress: Callable[[dict], None] | None = None, fft: str = "auto", **settings) -> Result:
    """Reconstruct a cube from one measurement; ``settings`` are the fields of ``Settings``."""
    solver = Solver(calibration, backend=backend, device=device, settings=Settings(**settings), fft=fft)
    return solver.solve(measurement, x0=x0, progress=progress)
