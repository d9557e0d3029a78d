"""ADMM with closed-form steps (Boyd et al. 2011; the splits of Antipa et al.'s DiffuserCam solver, with the filter
array's per-pixel inverse and the spectral TV's tridiagonal solve): :mod:`clsdcam.algorithms.admm` derives the
steps, and docs/admm.md has the measurements. One iteration is the c-step (the transforms) and then each split's
step with its dual:

    v, Hv ← c-step(x − ξ, u − η, w − ρ);   x, ξ ← x-step(Hv + ξ);   u, η ← u-step(Dv + η);   w, ρ ← w-step(v + ρ)

The iterate the driver sees is w, the non-negative copy of v. The penalties start relative to the problem's own scales
(so a brighter scene, another PSF normalisation or filter gain needs no new values): μ₁ = ``DATA``·mean‖f_p‖², μ₂ =
``TV``·μ₁·max|Ĥ|², μ₃ = ``NONNEG``·μ₁·max|Ĥ|² (:func:`penalties_for`; how they were chosen, and why residual balancing
is not used: docs/admm.md). After ``BALANCE_AT`` iterations the TV split's is set along each axis from the iterate's
differences, once (:mod:`.balance`); where the auto weights' probe finds the scene point-like (at the same iteration),
the non-negativity split's drops to ``NONNEG_POINT_LIKE`` while the balance widens its thresholds, and on a scene of a
few points to ``NONNEG_FEW_POINTS`` while the balance widens them further (:meth:`Admm.point_like`). A scene of a few
points that the probe's recount finds to be one of lit spots takes a point-like scene's penalties from there, its TV
balanced again (:meth:`Admm.lit_spots`). A scene of a few points in good light (the probe's noise σ̂ under
``GOOD_LIGHT_BELOW`` of max|b|) that is not of the fewest, under ``FEWEST_POINTS_PER_PIXEL`` lit voxels a window pixel,
is told point-like until the recount; found a few points there, it takes the few points' penalties, every one then
``LIGHTER_FEW_POINTS`` of itself, its TV balanced again (both readings the probe's:
:func:`clsdcam.solve.auto_weights.lighter_few_points`; :meth:`Admm.few_points_to_lighten`).

ADMM's objective is not monotone: :attr:`Admm.monotone` is False, so the checkpoints keep the best iterate (Ctrl-C
returns it) without rolling back on a rise. A video's next frame resumes from the last frame's splits and duals
(:meth:`Admm.carry`, :meth:`Admm.resume`); a warm start from a cube (``x0``) starts its duals afresh. It runs in
band space (``move`` refuses a change of space), on NumPy (:class:`~.host_steps.Splitting`, its passes compiled by
:class:`~.jit_steps.JitSplitting` where Numba is installed) and on backends with programs
(:class:`~.kernel_steps.KernelSplitting`): :func:`band_steps` picks them.
"""
from __future__ import annotations

from dataclasses import replace
from functools import cache
from typing import TYPE_CHECKING

from ...backends.base import Programs
from ...errors import InputError
from ...solve.auto_weights import AUTO_AT
from ...solve.priors import Sparsity, TotalVariation
from ..base import Algorithm, ratio

if TYPE_CHECKING:                 # the parser lists the algorithms: the steps' SciPy is imported when one solves
    from .terms import Penalties, SplittingBase

# the penalties and every split's over-relaxation α, chosen for the iterations to the model's answer
# (docs/convergence.md, "A faster ADMM"); docs/admm.md has the first choice, made for the first 100 iterations
DATA, TV, NONNEG = 1e-2, 1e-2, 1e-2
RELAXATION = 1.7
# μ₃'s constant on a point-like scene, from the probe's iteration on: the narrow-line scenes reach the model's answer
# in half the iterations or less (docs/convergence.md, "A lighter non-negativity penalty for point-like scenes")
NONNEG_POINT_LIKE = 3e-3
# and on a scene of a few points (the probe's count, clsdcam.solve.auto_weights.FEW_POINTS_PER_PIXEL): lighter still,
# the sixteen-source scenes reach their answer in about half the iterations (docs/convergence.md, "Lighter penalties
# for a few points")
NONNEG_FEW_POINTS = 1e-3
# and on a scene of a few points in good light, from the recount that finds it one, every penalty times
# LIGHTER_FEW_POINTS (μ₁ and μ₃ halved; the balance then sets μ₂,d from the thresholds): the three standard-light
# sixteen-source scenes the 3000-iteration cap held 0.4–1.0 dB short of their answer (112×144 to 160×192) come within
# it, a fresh 144×176 panel stops in 9 % fewer iterations and the 96×112 tuning scenes in 15 % more, all within; in low
# light the same change cost iterations (docs/convergence.md, "Halved penalties for a few points in good light"; all
# measured halved from AUTO_AT, before such scenes were told point-like until the recount). Good
# light, and the fewest points, are the probe's readings (clsdcam.solve.auto_weights.lighter_few_points, with their
# measured ranges). Not on the fewest, under FEWEST_POINTS_PER_PIXEL lit voxels a window pixel: the simulator's
# two-point scenes, halved, needed a stop at 0.01 (at 0.015 two of five ended 0.27–0.30 dB short of their answer);
# unhalved, nine of them stop 5 % sooner at 0.01, all within (docs/convergence.md, "A wider stop for a few points in
# good light")
LIGHTER_FEW_POINTS = 0.5
# conjugate-gradient steps of the margin's correction in each c-step (0: none; margin.py, and docs/convergence.md,
# "The margin's correction built"): 10 measured best of 0, 3 and 10
MARGIN_STEPS = 10
BALANCE_AT = AUTO_AT    # the TV split's penalties are balanced along each axis after this many iterations (balance.py)
# mean/peak of the iterate at AUTO_AT below which --tv auto takes a scene as point-like: 0.0005–0.0013 on five 128×160×64
# panels' lines scenes, 0.0035–0.21 on their other 80 (docs/convergence.md, "A lighter weight for point-like scenes")
POINT_LIKE_BELOW = 0.0025
# and at or above which it takes a scene as widely lit, whose weight rises in low light (TotalVariation.auto_weight's
# lit_variance): the geometric middle of the highest low-light scene measured to lose at the heavier weight (0.0630, a
# piecewise scene, which at 0.063 failed rule 4 by 0.09°) and the lowest above it measured to want it (0.0676, a
# sparse one), at 128×160×64; before it, 0.063, the same middle of 0.0586 and 0.068. Forty-one of forty-two
# low-light real cubes read 0.0699–0.147 there; below it one natural scene at 0.055 and one real cube at 0.058 want it
# too (docs/convergence.md, "A heavier weight for widely lit scenes in low light", "A lower widely lit threshold",
# "Fresh scenes on the widely lit threshold's code", "The threshold at 0.065")
WIDELY_LIT_ABOVE = 0.065


def penalties_for(split: "SplittingBase") -> "Penalties":
    """The penalties from the problem's scales (the module docstring)."""
    from .terms import Penalties

    data = DATA * split.data_curvature
    return Penalties(data=data, tv=TV * data * split.transfer_peak, nonneg=NONNEG * data * split.transfer_peak)


@cache
def host_steps() -> type:
    """The host's steps: :class:`~.jit_steps.JitSplitting`, the passes compiled, where Numba imports (the ``jit``
    extra), else NumPy's :class:`~.host_steps.Splitting` (Numba absent, or refusing this NumPy); chosen once a
    process, so a video's frames do not try a refused import again."""
    try:
        from .jit_steps import JitSplitting
    except ImportError:
        from .host_steps import Splitting

        return Splitting
    return JitSplitting


def band_steps(problem) -> "SplittingBase":
    """ADMM's steps for a band-space ``problem`` under its TV and L1 priors (what the settings let ADMM take): the
    kernels on a backend with programs (:class:`~clsdcam.backends.base.Programs`), else the host's steps
    (:func:`host_steps`); the calibration's terms from the solver's shared store. InputError in a subspace."""
    if problem.subspace is not None:
        raise InputError("--algorithm admm runs in band space: no --subspace or --rank")
    from .terms import calibration_terms

    tv = next((p for p in problem.priors if isinstance(p, TotalVariation)), None)
    l1 = next((p for p in problem.priors if isinstance(p, Sparsity)), None)
    model, terms, backend = problem.model, calibration_terms(problem), problem.backend
    if isinstance(backend, Programs):
        from .kernel_steps import KernelSplitting

        return KernelSplitting(model, problem.b, terms, tv, l1, RELAXATION, MARGIN_STEPS)
    return host_steps()(model, backend.to_host(problem.b), terms, tv, l1, backend.workers, RELAXATION, MARGIN_STEPS)


class Admm(Algorithm):
    """ADMM's state for one band-space problem (see the module docstring)."""

    name = "admm"
    monotone = False
    converges_soonest = True       # --algorithm auto's choice with --iters auto (docs/convergence.md)
    # field cubes it keeps, for the device's memory plan (cl_devices.problem_bytes): v, Hv, x, ρ, w, the rest, η and
    # s on three axes (12), the c-step's two spectra with the pivots (2.5), the start (1), the model's field and a
    # scratch (2); FISTA keeps 6
    field_buffers = 18
    band_space_only = True         # no splitting of a spectral subspace yet
    priors = ("tv", "l1")          # the priors it has a closed-form step for (band_steps)
    point_like_below = POINT_LIKE_BELOW
    widely_lit_above = WIDELY_LIT_ABOVE

    def __init__(self, backend, x0, step: float, rules):
        super().__init__(backend, x0, step, rules)
        self._start = backend.copy(x0)
        self.splitting: "SplittingBase | None" = None
        self.state = None
        self._resumed = None
        self._iterations = 0       # this solve's, for the TV penalties' balance at BALANCE_AT (balance.py)
        self._scene = "spread"     # the probe's word on the scene, for the balance's C and floor (balance.py)

    def iterate(self, problem) -> dict:
        if self.splitting is None:
            self._build(problem)
        if self._iterations == BALANCE_AT and self.splitting.axes and self.state.penalties.tv_balance is None:
            from .balance import balance

            balance(self.splitting, self.state, self.backend, self._scene)
        self._iterations += 1
        data, (step, norm) = self.splitting.iterate(self.state)
        return {"data": data, "change": ratio(step, norm)}

    def _build(self, problem) -> None:
        """The steps for ``problem``, and the state: a resumed one (with the penalties its duals are in), or a start
        from the iterate with fresh duals, in resumed penalties alone (a moved field's) or in the problem's own."""
        from .terms import Penalties

        self.splitting = band_steps(problem)
        resumed, self._resumed = self._resumed, None
        if isinstance(resumed, Penalties):
            self.splitting.set_penalties(resumed)
            self.reset(self.x)
        elif resumed is not None and resumed.v.shape == self.splitting.shape:
            self.splitting.set_penalties(resumed.penalties)
            self.state = resumed
        else:
            self.splitting.set_penalties(penalties_for(self.splitting))
            self.reset(self.x)

    def transforms(self, problem) -> int:
        """The c-step's: 2K forward and 2K inverse, every band, pruned ones counted as whole (after the first
        iteration built the steps)."""
        return self.splitting.transforms

    @property
    def x(self):
        """w, the non-negative copy of v (the start until the first iteration)."""
        return self._start if self.state is None else self.state.w

    def reset(self, point) -> None:
        """Start again from ``point`` with zero duals (the checkpoints' back-off)."""
        if self.splitting is None:
            self._start = self.backend.copy(point)
            return
        self.state, _ = self.splitting.start(point)

    def point_like(self, few_points: bool = False) -> str | None:
        """The scene is point-like (the auto weights' probe, :mod:`clsdcam.solve.auto_weights`): μ₃ from ``NONNEG`` to
        ``NONNEG_POINT_LIKE`` of the same scale, or ``NONNEG_FEW_POINTS`` on a scene of ``few_points``, the solve going
        on from the same point (:func:`.balance.repenalise`); the TV balance still to come sets wider thresholds, wider
        still on a scene of a few points, where it may also set lower penalties (:mod:`.balance`). Returns the line that
        says so (None before the first iteration, when only the balance is told)."""
        self._scene = "few_points" if few_points else "point_like"
        if self.state is None:
            return None
        from .balance import repenalise

        factor = (NONNEG_FEW_POINTS if few_points else NONNEG_POINT_LIKE) / NONNEG
        repenalise(self.splitting, self.state, self.backend,
                   replace(self.splitting.penalties, nonneg=self.splitting.penalties.nonneg * factor))
        return (f"admm: μ₃ × {factor:g}, wider TV thresholds (a scene of a few points)" if few_points
                else f"admm: μ₃ × {factor:g}, wider TV thresholds (a point-like scene)")

    def lit_spots(self) -> str | None:
        """The scene told to be of a few points is one of lit spots (the probe's recount): from here on the penalties
        of a point-like scene, the camera's (:func:`penalties_for`) with μ₃ at ``NONNEG_POINT_LIKE``, and the TV split
        balanced again from the iterate with the spread scenes' C and floor (:meth:`_retake`). Returns the line that
        says so (None before the first iteration)."""
        if self._retake("spread", NONNEG_POINT_LIKE):
            return f"admm: μ₃ × {NONNEG_POINT_LIKE / NONNEG:g} of the camera's, TV balanced again (lit spots)"
        return None

    def few_points_to_lighten(self) -> str | None:
        """The scene told point-like in good light is, counted again (the probe's recount), one of a few points not of
        the fewest: from here on the camera's penalties with μ₃ at ``NONNEG_FEW_POINTS``, every one then
        ``LIGHTER_FEW_POINTS`` of itself, and the TV split balanced again from the iterate with the few points' C and
        floor (:meth:`_retake`). Returns the line that says so (None before the first iteration)."""
        if self._retake("few_points", NONNEG_FEW_POINTS, LIGHTER_FEW_POINTS):
            return (f"admm: μ₃ × {NONNEG_FEW_POINTS / NONNEG:g} of the camera's, every penalty × "
                    f"{LIGHTER_FEW_POINTS:g}, wider TV thresholds (a few points in good light)")
        return None

    def _retake(self, scene: str, nonneg: float, scale: float = 1.0) -> bool:
        """The camera's penalties (:func:`penalties_for`) with μ₃ at ``nonneg`` of μ₂'s scale, every one times
        ``scale``, the duals carried over (:func:`.balance.repenalise`), then the TV balanced again from the iterate
        with the ``scene``'s C and floor (:func:`.balance.balance`), which the balance reads from then on. False
        before the first iteration (nothing to retake: only the scene is kept)."""
        self._scene = scene
        if self.state is None:
            return False
        from .balance import balance, repenalise

        camera = penalties_for(self.splitting)
        repenalise(self.splitting, self.state, self.backend,
                   replace(camera, nonneg=camera.nonneg * nonneg / NONNEG).scaled(scale))
        balance(self.splitting, self.state, self.backend, scene)
        return True

    def carry(self):
        """What the next frame's solve resumes from: the splits and duals (None before the first iteration)."""
        return self.state

    def resume(self, state, factor: float) -> None:
        """Go on from a previous solve's splits and duals (:meth:`carry`), every array times ``factor`` (its units to
        this solve's: the problem is homogeneous in b), instead of starting the duals afresh; or, given its penalties
        alone (what a moved field keeps: ``SplitState.moved``), start the duals afresh in them (balanced once and in
        the probe's reading, they are not set again)."""
        from .terms import Penalties

        if not isinstance(state, Penalties):
            for array in state.arrays():
                self.backend.scale(factor, array, out=array)
            state.margin_band = None         # the margin's correction starts its band again (margin.py)
        self._resumed = state
