"""A plug-in with a sub-problem of its own (tests/test_algorithms.py registers it): the primal-dual method of Condat
(2013) and Vũ (2013) for

    min_{v ≥ 0} ½‖Av − b‖² + τ Σ_d w_d ‖D_d v‖₁,

the exact anisotropic TV (ADMM's u-split's, not FISTA's Haar average), with a dual y_d per TV axis:

    v⁺  = max(0, v − s·(∇f(v) + Σ_d D_dᵀ y_d))                  (problem.gradient_step, then the dual's push)
    y_d⁺ = clip(y_d + σ·D_d(2v⁺ − v), ±τ·w_d)                   (the sub-problem: prox of the conjugate of τw_d‖·‖₁)

It converges for 1/s − σ‖D‖² ≥ L/2; with the driver's s = 1/L and ‖D‖² ≤ 4 per axis, σ = 1/(2·4·n_axes·s).
The dual is a sub-problem object built, at the first iteration, from what the problem hands an algorithm (its priors
and the shared store, clsdcam.solve.problem.Problem); it runs on the host, so the plug-in runs on any backend; a video's
next frame resumes from the last frame's dual (``carry``/``resume``). One module, nothing of the package touched.
"""
import numpy as np

from clsdcam.algorithms.admm.host_steps import difference, difference_adjoint_add
from clsdcam.algorithms.base import Algorithm, ratio
from clsdcam.solve.priors import TotalVariation


class TvDual:
    """The dual sub-problem: y_d for each active TV axis of one band-space problem, on the host."""

    def __init__(self, tv: TotalVariation, shape):
        self.tv = tv
        self.axes = [axis for axis, weight in enumerate(tv.axis_weights) if weight > 0]
        self.y = np.zeros((len(self.axes),) + tuple(shape))
        self._d = np.empty(shape)

    def push(self, v: np.ndarray, step: float, out: np.ndarray) -> np.ndarray:
        """out = v − step·Σ_d D_dᵀ y_d."""
        np.copyto(out, v)
        for i, axis in enumerate(self.axes):
            difference_adjoint_add(self.y[i], axis, -step, out)
        return out

    def ascend(self, v_bar: np.ndarray, sigma: float) -> None:
        """y_d ← clip(y_d + σ·D_d v̄, ±τw_d), τ read now (an automatic weight chosen mid-solve counts at once)."""
        for i, axis in enumerate(self.axes):
            limit = self.tv.weight * self.tv.axis_weights[axis]
            self.y[i] += sigma * difference(v_bar, axis, self._d)
            np.clip(self.y[i], -limit, limit, out=self.y[i])


class PrimalDual(Algorithm):
    name = "pdhg"
    monotone = False             # F may rise on the way; the checkpoints keep the best
    band_space_only = True
    priors = ("tv",)

    def __init__(self, backend, x0, step: float, rules):
        super().__init__(backend, x0, step, rules)
        self.x, self.z = backend.copy(x0), backend.copy(x0)
        self.dual: TvDual | None = None
        self._resumed = None

    def iterate(self, problem) -> dict:
        if self.dual is None:
            self.dual = self._build_dual(problem)
        be, dual = self.backend, self.dual
        data = problem.gradient_step(self.x, self.z, self.step)
        before = be.to_host(self.x).astype(np.float64)
        stepped = dual.push(be.to_host(self.z).astype(np.float64), self.step, np.empty_like(before))
        after = np.maximum(stepped, 0.0)
        if dual.axes:
            dual.ascend(2.0 * after - before, 1.0 / (8.0 * len(dual.axes) * self.step))
        be.copy(be.to_device(after.astype(be.dtype)), out=self.x)
        moved = after - before
        return {"data": data, "change": ratio(float(np.vdot(moved, moved)), float(np.vdot(after, after)))}

    def _build_dual(self, problem) -> TvDual:
        """The sub-problem from the problem's TV prior (a zero-weight TV when it has none), resumed if carried."""
        tv = next((p for p in problem.priors if isinstance(p, TotalVariation)), None)
        dual = TvDual(tv if tv is not None else _NoTv(), problem.model.cube_shape)
        if self._resumed is not None and self._resumed.shape == dual.y.shape:
            dual.y = self._resumed
        self._resumed = None
        return dual

    def reset(self, point) -> None:
        self.backend.copy(point, out=self.x)
        if self.dual is not None:
            self.dual.y[...] = 0.0

    def carry(self):
        return None if self.dual is None else self.dual.y

    def resume(self, carried, factor: float) -> None:
        self._resumed = carried * factor


class _NoTv:
    weight, axis_weights = 0.0, (0.0, 0.0, 0.0)
