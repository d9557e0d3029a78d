"""Solver settings: the loop's and the skips' fields, plus one weight per prior of :data:`clsdcam.solve.priors.PRIORS`
(generated from the table, so a new prior is a field and a ``--flag`` without touching this file).

Weights are relative to the data (see :mod:`clsdcam.solve.priors`). Every value is checked on construction
(an :class:`~clsdcam.errors.InputError` naming the option).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, make_dataclass

import numpy as np

from ..algorithms import ALGORITHMS
from ..errors import InputError
from .priors import AUTO, PRIORS

DEFAULT_ITERS = AUTO  # iterate until converged (``converge``), at most AUTO_CAP
AUTO_CAP = 3000       # the most iterations an automatic stop runs (the panel's references' length, docs/convergence.md)
CONVERGE = 0.05       # the estimated relative distance to the limit an automatic stop stops at (docs/convergence.md)
CONVERGE_WIDE = 0.1   # --converge auto's, once the point-like probe reads a scene that is not point-like (nor sparse
#                       in good light: clsdcam.solve.auto_weights.SPARSE_BELOW)
COLD_ITERS = 40     # a stream's cold start (a batch chunk's first frame): what reached a cold solve's accuracy (with --subspace, docs/batch.md)
DEFAULT_TOL = 0.0


@dataclass(frozen=True)
class SolverSettings:
    """The fields that are not prior weights."""

    iters: int | str = DEFAULT_ITERS   # a count, or "auto": until converged, at most AUTO_CAP
    converge: float | str = AUTO   # with iters "auto": stop when the estimated distance to the limit is below this;
    #                                 auto: CONVERGE, widened to CONVERGE_WIDE where the probe at AUTO_AT allows
    algorithm: str = "auto"        # a name of clsdcam.algorithms.ALGORITHMS, or "auto" (resolved on construction)
    tv_weights: tuple[float, float, float] = (1.0, 1.0, 1.0)  # x, y, λ
    tol: float = DEFAULT_TOL
    plateau: float = 0.0           # stop when F fell by less than this (relative) between checkpoints
    skip: bool = True              # skip what the scene doesn't need (False: the full solver)
    rank: int = 0                  # spectral basis vectors: R < K forces a subspace of R; 0 = as ``subspace`` says
    subspace: bool = False         # enter a spectral subspace of automatic size (faster; uncertified: see phases)
    support_field: bool = False    # the PSF support's field instead of the paper's 2H × 2W (faster; uncertified: skips)
    dtype: str = "float32"
    objective_every: int = 10      # F(x) evaluated (and the best iterate kept) this often
    restart: bool = True           # adaptive momentum restart (O'Donoghue–Candès)
    step_scale: float = 1.0        # step = step_scale / L; > 1 only to test the back-off
    full_field: bool = False

    def __post_init__(self):
        object.__setattr__(self, "tv_weights", tuple(float(w) for w in self.tv_weights))
        if self.algorithm == AUTO:
            object.__setattr__(self, "algorithm", self._auto_algorithm())
        _require(self.iters == AUTO or (_is_int(self.iters) and self.iters >= 1),
                 f"--iters {self.iters}: must be auto or an integer ≥ 1")
        _require(self.algorithm in ALGORITHMS,
                 f"--algorithm {self.algorithm!r}: expected one of {', '.join(ALGORITHMS)}")
        _require(_finite_nonneg(self.step_scale) and self.step_scale > 0, f"step_scale {self.step_scale}: must be > 0")
        _require(_is_int(self.rank) and self.rank >= 0, f"--rank {self.rank}: must be an integer ≥ 0")
        _require(self.converge == AUTO or (_finite_nonneg(self.converge) and self.converge > 0),
                 f"--converge {self.converge}: must be auto or a number > 0")
        for name in ("tol", "plateau"):
            value = getattr(self, name)
            _require(_finite_nonneg(value), f"--{name} {value}: must be a finite number ≥ 0")
        for row in PRIORS:
            value = getattr(self, row.name)
            if value == AUTO and row.prior.auto_weight:
                continue
            _require(_finite_nonneg(value), f"{row.flag} {value}: must be a finite number ≥ 0"
                     + (" or auto" if row.prior.auto_weight else ""))
        self._check_algorithm_limits(ALGORITHMS[self.algorithm])
        _require(len(self.tv_weights) == 3 and all(_finite_nonneg(w) for w in self.tv_weights),
                 f"--tv-weights {self.tv_weights}: expected three finite numbers ≥ 0 (x, y, λ)")
        _require(self.objective_every >= 1, f"objective_every {self.objective_every}: must be ≥ 1")

    @property
    def budget(self) -> int:
        """The most iterations a solve runs: ``iters``, or AUTO_CAP when it is "auto"."""
        return AUTO_CAP if self.iters == AUTO else self.iters

    @property
    def stop_distance(self) -> float:
        """The driver's ``converge`` rule at the start: ``converge`` (CONVERGE for auto) when ``iters`` is "auto",
        else 0 (off)."""
        if self.iters != AUTO:
            return 0.0
        return CONVERGE if self.converge == AUTO else self.converge

    @property
    def wide_stop(self) -> float | None:
        """The tolerance the stop may widen to once the point-like probe reads a scene that is not point-like
        (:class:`clsdcam.solve.auto_weights.AutoWeights`): CONVERGE_WIDE with ``--iters auto --converge auto``,
        else None (the tolerance stays)."""
        return CONVERGE_WIDE if self.iters == AUTO and self.converge == AUTO else None

    def _auto_algorithm(self) -> str:
        """``--algorithm auto``: for a solve run until converged (``--iters auto``), the first algorithm that declares
        itself the one to converge with (:attr:`~clsdcam.algorithms.base.Algorithm.converges_soonest`: ADMM, whose
        steps shrink smoothly enough for the stop to trust, where FISTA's restarts fool it, docs/convergence.md) and
        can run these settings; FISTA for a fixed number of iterations (its path is the better one at a budget) and
        for everything else."""
        if self.iters == AUTO:
            for name, algorithm in ALGORITHMS.items():
                if algorithm.converges_soonest and self._algorithm_limit(name, algorithm) is None:
                    return name
        return "fista"

    def _check_algorithm_limits(self, algorithm):
        limit = self._algorithm_limit(self.algorithm, algorithm)
        _require(limit is None, limit)

    def _algorithm_limit(self, name: str, algorithm) -> str | None:
        """What the algorithm declares it cannot do yet (:mod:`clsdcam.algorithms.base`) and these settings ask
        for (a subspace, other priors), as the message that refuses them; None: nothing."""
        if algorithm.band_space_only and (self.subspace or self.rank):
            return f"--algorithm {name} runs in band space: drop --subspace and --rank (or use --algorithm fista)"
        stepped = algorithm.priors
        others = [row.flag for row in PRIORS if stepped is not None and row.name not in stepped
                  and getattr(self, row.name) != 0]
        if others:
            return (f"--algorithm {name} has steps for {' and '.join('--' + p for p in stepped)} only, "
                    f"not {', '.join(others)} (use --algorithm fista)")
        return None


Settings = make_dataclass(
    "Settings", [(row.name, float | str, field(default=row.default)) for row in PRIORS], bases=(SolverSettings,),
    frozen=True, namespace={"__doc__": "Solver settings: SolverSettings' fields and one relative weight per prior "
                                       "(clsdcam.solve.priors.PRIORS: " + ", ".join(row.name for row in PRIORS) + ").",
                                       "__module__": __name__})


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


def _finite_nonneg(value) -> bool:
    return isinstance(value, (int, float, np.floating, np.integer)) and math.isfinite(value) and value >= 0


def _require(condition: bool, message: str):
    if not condition:
        raise InputError(message)
