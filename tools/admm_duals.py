"""ADMM's duals set at their fixed-point values for a given cube, and a second TV balance: two ideas measured as
``bench_converged --variants`` (names ``duals``, ``refresh`` and ``rebalance``) and not built into the solver
(docs/convergence.md, "What was tried and lost", has their numbers).

At ADMM's fixed point every split equals its argument (x = Hv, u_d = D_d v, w = v), and each scaled dual is what its
split's optimality leaves (:func:`fixed_point_duals`, for the cube w ≥ 0 taken as v):

* the data split's, from the x-step: ξ_p = −f_p·(b_p − f_pᵀ(Hw)_p)/μ₁ on the sensor window;
* the TV split's, from the soft threshold: η_d = t_d·sign(D_d w) where D_d w ≠ 0, in [−t_d, t_d] where it is 0,
  taken as t_d·clip(D_d w/(``SHARP``·t_d), −1, 1);
* the non-negativity split's, from the c-step's optimality in v, μ₁Hᵀξ + Σ_d μ₂,d D_dᵀη_d + μ₃ρ = 0: ρ = 0 where
  w > 0, min(0, −(μ₁Hᵀξ + Σ_d μ₂,d D_dᵀη_d)/μ₃) where w = 0.

The start's duals are zero, and ADMM builds them at its penalties' pace: after its first x-step ξ is
μ₁/(μ₁ + ‖f_p‖²), about a hundredth at the camera's μ₁, of its fixed-point value for the same residual. ``duals=1``
(ξ, over the start's first split pass, which leaves η_d = clip(D_d v0, ±t_d) and ρ) or ``duals=2`` (all three)
sets them from the variant's start (its ``fista_start`` or ``answer_start`` cube); ``refresh=N`` sets them again
from the iterate w at iteration N (``duals`` the kind, 1 if not named); ``rebalance=N`` balances the TV penalties
again at iteration N (:func:`clsdcam.algorithms.admm.balance.balance`, from the iterate then). Host steps only
(``--backend numpy``).
"""
from __future__ import annotations

from contextlib import contextmanager

import numpy as np
import scipy.fft

SHARP = 0.01          # η_d's ramp: |D_d w| under SHARP·t_d counts as flat
DUAL_VARIANTS = ("duals", "refresh", "rebalance")
XI_ALONE, EVERY_DUAL = 1, 2


def fixed_point_duals(split, state, w: np.ndarray, kind: int = EVERY_DUAL) -> None:
    """Set ``state``'s splits to ``w``'s (x = Hw, w) and its duals to their fixed-point values for w (the module
    docstring): ξ, and with ``kind`` EVERY_DUAL also η_d (with s_d = D_d w − η_d) and ρ; then what the next c-step
    reads of them (x − ξ, μ₃(w − ρ) in ``rest``)."""
    from clsdcam.algorithms.admm.host_steps import difference, difference_adjoint_add

    p, (h, wd) = split.penalties, split.sensor_shape
    w = np.maximum(np.asarray(w, split.dtype), 0)
    hw = split.convolve(w).astype(split.dtype)
    misfit = split.b - np.einsum("khw,khw->hw", split.filters, hw[:, :h, :wd])
    split.set_data_split(state, hw, -split.filters * (misfit / p.data))
    state.w[...] = w
    if kind != EVERY_DUAL:
        return
    for i, axis in enumerate(split.axes):
        d, t = difference(w, axis, np.empty_like(w)), split.threshold(axis)
        state.eta[i] = t * np.clip(d / (SHARP * t), -1, 1)
        state.s[i] = d - state.eta[i]
    pushed = np.zeros_like(w)
    pushed[:, :h, :wd] = state.xi
    data_transfer = split.terms.for_penalties(p, split.axes).data_transfer        # μ₁conj(Ĥ), the c-step's own
    gradient = scipy.fft.irfft2(scipy.fft.rfft2(pushed) * data_transfer, s=split.field_shape)
    for i, axis in enumerate(split.axes):
        difference_adjoint_add(state.eta[i], axis, p.tv_along(axis), gradient)
    state.rho[...] = np.where(w > 0, 0, np.minimum(0, -gradient / p.nonneg))
    state.rest[...] = p.nonneg * (state.w - state.rho)


@contextmanager
def dual_variants(variant: dict, events: dict):
    """While it lasts, ADMM's host start and iteration do what ``variant``'s ``duals``, ``refresh`` and
    ``rebalance`` name (nothing if it names none), each setting counted in ``events["restarts"]``; restored
    after."""
    from clsdcam.algorithms.admm.algorithm import Admm
    from clsdcam.algorithms.admm.balance import balance
    from clsdcam.algorithms.admm.host_steps import Splitting

    start, iterate = Splitting.start, Admm.iterate
    kind = int(variant.get("duals", XI_ALONE))
    refresh, rebalance = int(variant.get("refresh", 0)), int(variant.get("rebalance", 0))

    def derived_start(split, v0):
        state, data = start(split, v0)
        fixed_point_duals(split, state, v0, kind)
        events["restarts"] += 1
        return state, data

    def later(admm, problem):
        if admm.state is not None and admm._iterations in (refresh, rebalance):
            if admm._iterations == rebalance and admm.splitting.axes:
                balance(admm.splitting, admm.state, admm.backend, admm._scene)
            if admm._iterations == refresh:
                fixed_point_duals(admm.splitting, admm.state, admm.state.w.copy(), kind)
            events["restarts"] += 1
        return iterate(admm, problem)

    if "duals" in variant and not refresh:
        Splitting.start = derived_start
    if refresh or rebalance:
        Admm.iterate = later
    try:
        yield events
    finally:
        Splitting.start, Admm.iterate = start, iterate
