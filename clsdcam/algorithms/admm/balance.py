"""The TV split's penalty balanced along each axis, once (docs/convergence.md, "Balanced TV penalties").

The u-step soft-thresholds D_d v + η_d at t_d = τw_d/μ₂,d. With one μ₂ for every axis, set from the camera's scales
alone, t_d bears no relation to the cube's own differences: on the tuning panel it was 0.6–1.8 times their RMS on
a scene of narrow lines, 11–26 times on natural and real ones, and ADMM is slow at both ends.
After :data:`~.algorithm.BALANCE_AT` iterations (when ``--tv auto`` has chosen τ and the iterate has its edges),
each active axis's penalty is set so its threshold is ``THRESHOLD_OVER_RMS`` times the RMS of the iterate's
differences along it:

    μ₂,d = τw_d / (C·rms(D_d w)),   C = THRESHOLD_OVER_RMS,

held within a factor ``BALANCE_RANGE`` of the camera's μ₂ (a flat or black cube's RMS says nothing). On a point-like
scene that is not of a few points (the narrow-line LED spots the probe flags) C is ``THRESHOLD_POINT_LIKE``: its
differences' RMS is the black field's more than the spots' edges, and C = 2 there left ADMM 1.1–2.3 times as many
iterations to its stop (docs/convergence.md, "Wider TV thresholds for point-like scenes"). On a scene of a few points
(the probe's count, :mod:`clsdcam.solve.auto_weights`) C is ``THRESHOLD_FEW_POINTS``: the RMS over a black cube is set
by how few voxels are lit, far below the points' own edges, and C = 2 there left ADMM hundreds to thousands of
iterations slower (docs/convergence.md, "Wider TV thresholds for a few points"); and β_d may fall to
``FLOOR_FEW_POINTS`` there, where the floor 1/``BALANCE_RANGE`` held the sixteen-source scenes' penalties up to 4 times
above what C asks ("Lighter penalties for a few points"). The RMS is the splitting's ``difference_rms``: on
the host, each band's squares summed in w's precision and the bands' in float64 (:func:`.host_steps.difference_rms`);
on the kernels, one reduction over w on the device with its sums in the accumulators (``admm_difference_squares``),
which reads back three sums where w itself (147 MB at full size) was read before. The two agree to the rounding of
the host's float32 dot products (tests/test_parity.py), so both backends set the same penalties to that rounding.

Any change of penalties between two iterations (the balance's, a point-like scene's, :func:`repenalise`) keeps
every unscaled dual, so the iteration goes on from the same point with new pivots (ADMM's fixed point, the splits
and the unscaled duals, does not depend on the penalties):

* μ₂,d → μ₂,d': η_d ← r_d·η_d and s_d ← s_d + (1 − r_d)η_d with r_d = μ₂,d/μ₂,d', so u_d = s_d + η_d stays;
* μ₃ → μ₃': ρ ← (μ₃/μ₃')ρ, and the c-step's right-hand side μ₃(w − ρ), which the last w-step left in ``rest``,
  becomes μ₃'(w − ρ') = rest + (μ₃' − μ₃)w;
* μ₁ → μ₁': ξ ← r·ξ with r = μ₁/μ₁', and the data term's x − ξ, which the last x-step left in ``hv`` on the sensor
  window, becomes x − ξ' = hv + (1 − r)ξ there (on the host ``hv`` holds the window's change to x − ξ, to which the
  same (1 − r)ξ is added: :mod:`.host_steps`).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .terms import Penalties, SplitState, SplittingBase

THRESHOLD_OVER_RMS = 2.0      # C: chosen on the tuning panel (docs/convergence.md)
# C on a point-like scene not of a few points (docs/convergence.md, "Wider TV thresholds for point-like scenes")
THRESHOLD_POINT_LIKE = 8.0
# C on a scene of a few points (the probe's count, clsdcam.solve.auto_weights.FEW_POINTS_PER_PIXEL): the differences'
# RMS over a black cube is far below the points' own edges (docs/convergence.md, "Wider TV thresholds for a few points")
THRESHOLD_FEW_POINTS = 16.0
BALANCE_RANGE = 64.0          # β_d within [1/64, 64]
# the floor of β_d on a scene of a few points: with C = 16 the sixteen-source scenes ask 1/130–1/260 of the camera's
# penalty, and held at 1/64 they reach their answer hundreds of iterations later (docs/convergence.md, "Lighter
# penalties for a few points")
FLOOR_FEW_POINTS = 1.0 / 4096


def balanced_penalties(split: SplittingBase, rms: dict[int, float], threshold_over_rms: float,
                       floor: float = 1.0 / BALANCE_RANGE) -> Penalties:
    """The penalties with each active axis's β_d = τw_d/(C·rms_d·μ₂), C = ``threshold_over_rms``, held within
    [``floor``, BALANCE_RANGE] (the module docstring); an axis whose differences are all zero, or the whole TV when its
    weight is zero, keeps its β_d."""
    p, tau = split.penalties, split.tv.weight
    betas = [1.0, 1.0, 1.0] if p.tv_balance is None else list(p.tv_balance)
    for axis, value in rms.items():
        if value > 0 and tau > 0:
            beta = tau * split.tv.axis_weights[axis] / (threshold_over_rms * value * p.tv)
            betas[axis] = float(np.clip(beta, floor, BALANCE_RANGE))
    return replace(p, tv_balance=tuple(betas))


def threshold_and_floor(scene: str) -> tuple[float, float]:
    """C and the floor of β_d for a ``scene`` the probe read as "spread" (or not read), "point_like" or "few_points"
    (the module docstring); any other name is a KeyError. Read when called, so the constants may be set meanwhile."""
    return {"spread": (THRESHOLD_OVER_RMS, 1.0 / BALANCE_RANGE),
            "point_like": (THRESHOLD_POINT_LIKE, 1.0 / BALANCE_RANGE),
            "few_points": (THRESHOLD_FEW_POINTS, FLOOR_FEW_POINTS)}[scene]


def balance(split: SplittingBase, state: SplitState, backend, scene: str = "spread") -> Penalties:
    """Set the balanced penalties from the RMS of the iterate's differences (the splitting's own
    ``difference_rms``, on the device on the kernels), C and the floor the ``scene``'s (:func:`threshold_and_floor`),
    the duals carried over (:func:`repenalise`) with ``backend``'s operations. Returns them."""
    threshold, floor = threshold_and_floor(scene)
    rms = split.difference_rms(state)
    return repenalise(split, state, backend, balanced_penalties(split, rms, threshold, floor))


def repenalise(split: SplittingBase, state: SplitState, backend, new: Penalties) -> Penalties:
    """Go on under the ``new`` penalties between two iterations, every unscaled dual kept (the module docstring) with
    the backend's vector operations; the state records them (a video's next frame resumes with them). Returns
    them."""
    old = split.penalties
    if new.data != old.data:
        keep = old.data / new.data
        window = backend.pad(state.xi, state.hv.shape[-2:], (0, 0))     # the field's, or the window's on the host
        backend.axpy(1.0 - keep, window, state.hv, out=state.hv)
        backend.scale(keep, state.xi, out=state.xi)
        state.margin_band = None                  # the margin's correction starts its band again (margin.py)
    ratios = {axis: old.tv_along(axis) / new.tv_along(axis) for axis in split.axes}
    if any(ratio != 1.0 for ratio in ratios.values()):
        split.rescale_tv_duals(state, ratios)
    if new.nonneg != old.nonneg:
        backend.scale(old.nonneg / new.nonneg, state.rho, out=state.rho)
        backend.axpy(new.nonneg - old.nonneg, state.w, state.rest, out=state.rest)
    split.set_penalties(new)
    state.penalties = new
    return new
