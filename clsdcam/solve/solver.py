"""Reconstruction: one measurement + a calibration -> a hyperspectral cube.

    argmin_{v ≥ 0} ½‖b − Av‖² + Σ_i τ_i·φ_i(v)     by an algorithm of :mod:`clsdcam.algorithms` (FISTA), step 1/L

with the priors φ_i of :mod:`clsdcam.solve.priors` (TV by default). The solver builds the model once per calibration;
each solve is a :class:`~clsdcam.solve.reconstruction.Reconstruction`, which builds its start
(:mod:`clsdcam.solve.state`),
priors, spaces (:mod:`clsdcam.solve.spaces`) and algorithm, and hands them to the phases
(:mod:`clsdcam.solve.phases`), which run
the driver (:mod:`clsdcam.solve.driver`).

Units. The measurement is used as given. Internally it is divided by s = max|b| (the solver's
units: the driver's records, objective and checkpoints are all in them); the result's cube, snapshots and history
are turned back into data units at the edge, by one :class:`~clsdcam.solve.units.Units` per solve. The user's weights
are relative to the data
(each prior's reference, see :mod:`clsdcam.solve.priors`), so scaling the measurement by s scales the
cube by s, and the same weights suit any PSF or filter normalisation.

Skips (``skip=True``, the default; ``skip=False`` is the full solver: the paper's field, every
band, every iteration in band space): no FFTs for bands no filter sees, pruned transforms on the host
path, zero-weight terms never evaluated: all exact, so the default solves ``--no-skip``'s
problem on its field. Two speed options change the problem and are taken only when asked: the spectral
subspace (``subspace=True`` or ``rank``, see :mod:`clsdcam.solve.space_policy`) and the support-sized field
(``support_field=True``, see :mod:`clsdcam.solve.skips`); docs/accuracy.md says why neither is the default.
Each is reported in ``Result.attrs["skips"]`` with the FFT work it saved.
"""
from __future__ import annotations

from dataclasses import asdict
from typing import Callable

import numpy as np

from ..algorithms import ALGORITHMS
from ..backends import get_backend
from ..errors import InputError, shape_text
from ..io import require_finite
from ..camera.model import ForwardModel
from .reconstruction import Reconstruction
from .result import Result
from .settings import Settings
from .skips import plan_geometry
from .spaces import LastLipschitz
from .state import SolverState

__all__ = ["Result", "Settings", "Solver", "reconstruct"]


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
        self.last_lipschitz = LastLipschitz()    # L of the last spectral subspace: reused for the same basis
        self.shared: dict = {}    # what algorithms build once per calibration (clsdcam.solve.problem.Problem.shared)

    def solve(self, measurement: np.ndarray, x0: np.ndarray | None = None,
              progress: Callable[[dict], None] | None = None, snapshots=(), state: SolverState | None = None,
              iters: int | None = None, stop_at_fit: float | None = None) -> Result:
        """Reconstruct one (H, W) measurement.

        x0 is an optional warm start in data units: a (K, H, W) cube or a whole field (``Result.full_field``);
        ``state`` (a previous ``Result.state`` of this solver, e.g. the last frame of a video) starts from its
        field instead and carries its basis, rank, step and weights (:mod:`clsdcam.solve.state`); ``snapshots`` lists
        iterations at which a copy of the cube is kept in ``Result.snapshots`` (e.g. to measure accuracy);
        ``iters`` overrides ``Settings.iters`` for this solve (a stream's cold and warm frames); ``stop_at_fit``
        stops it (reason "fit") once ‖Ay − b‖/‖b‖ at the algorithm's gradient point is at most that (e.g. the
        previous frame's fit: a frame that changed little stops early, one that changed more gets the iterations).
        """
        return Reconstruction(self, measurement, x0=x0, state=state).run(progress, snapshots, iters, stop_at_fit)

    # ---- pieces -------------------------------------------------------------------------
    def _check_memory(self):
        """Devices with their own memory say up front (InputError) when the problem cannot fit."""
        check = getattr(self.backend, "check_problem", None)
        if check is not None:
            cubes = ALGORITHMS[self.settings.algorithm].field_buffers
            check(self.geometry.sensor, self.geometry.field, self.calibration.filters.shape[0], field_buffers=cubes)

    def checked(self, measurement) -> np.ndarray:
        """The measurement as float64, refused (InputError) when its shape is not the calibration's or it is not
        finite."""
        b = np.asarray(measurement, dtype=np.float64)
        if b.shape != self.model.sensor_shape:
            raise InputError(f"measurement {shape_text(b.shape)} does not match calibration {shape_text(self.model.sensor_shape)}")
        return require_finite(b, "measurement")

    def settings_attrs(self) -> dict:
        """The attributes every result of this solver records: its settings and where it ran."""
        be = self.backend
        return {**asdict(self.settings), "backend": be.name, "device": be.device_name, "path": be.path,
                "fft_engine": be.fft_engine}


def reconstruct(measurement, calibration, backend="numpy", device: str | None = None, x0=None,
                progress: Callable[[dict], None] | None = None, fft: str = "auto", path: str = "auto",
                preprocessing=None, **settings) -> Result:
    """Reconstruct a cube from one measurement (an array or an image/.npy/.h5 path) with a calibration (a
    :class:`~clsdcam.camera.calibration.Calibration` or a file path), preprocessed as the command line does
    (``preprocessing``: a :class:`~clsdcam.camera.calibration.Preprocessing`, default its defaults); the cube comes
    back in the calibration's units. ``settings`` are the fields of ``Settings``. ``backend`` (also
    :class:`Solver`'s): ``"numpy"`` by default, the reference, the same result on every machine; ``"opencl"``; or
    ``"auto"``, the command line's default (:func:`clsdcam.backends.resolve_backend`: OpenCL on a GPU when one is
    found, else NumPy)."""
    from ..calibrate.measurement import prepare

    calibration, measurement = prepare(measurement, calibration, preprocessing)
    solver = Solver(calibration, backend=backend, device=device, settings=Settings(**settings), fft=fft, path=path)
    return solver.solve(measurement, x0=x0, progress=progress)
