"""Three accelerations of ADMM, measured as ``bench_converged --variants`` (names ``momentum``, ``anderson`` and
``spectral``) and not built into the solver (docs/convergence.md, "What was tried and lost", has their numbers).
Each wraps the host steps' iteration (:class:`~clsdcam.algorithms.admm.host_steps.Splitting`) for the duration of a
variant. Inner products are accumulated in float64 (:func:`inner`).

ADMM as a fixed-point map. Each split takes the point q = α·K v + (1 − α)·z + y (K the split's operator: H, D_d
or I; z its variable, y its scaled dual), sets z = prox(q) and y = q − z, and the next c-step reads z − y. So q, on
the three splits (data, TV per axis, non-negativity), is the whole state: one iteration is a map q ← T(q), and q
is read back from the state as x + ξ (ξ on the sensor window only), u_d + η_d = s_d + 2η_d and w + ρ
(:func:`split_inputs`), and written by the splits' proxes (:func:`set_split_inputs`). Norms weight each split by
its penalty: ‖q‖² = μ₁‖q_data‖² + μ₂Σ‖q_d‖² + μ₃‖q_nonneg‖².

* **momentum** = η: Goldstein, O'Donoghue, Setzer and Baraniuk 2014 (fast ADMM for weakly convex problems, their
  Algorithm 8): Nesterov's extrapolation of the splits and duals, ẑ = z_k + (a_k − 1)/a_{k+1}·(z_k − z_{k−1}) and
  the same for y, restarted (a = 1, back to z_{k−1}, y_{k−1}) whenever the combined residual
  c_k = Σ μ(‖y_k − ŷ_k‖² + ‖z_k − ẑ_k‖²) fails to fall below η·c_{k−1}. Every array of the state after the splits is
  linear in (z, y), so each is extrapolated alike.
* **anderson** = m: type-II Anderson acceleration of T with memory m: with f = T(q) − q, the point
  T(q_k) − Σ_j γ_j ΔT_j where γ minimises ‖f_k − Σ_j γ_j Δf_j‖ over the last m differences; safeguarded as Zhang
  et al. 2019 accelerate ADMM: an extrapolated point whose residual ‖f‖ does not fall is dropped for the plain step
  from the point before, and the memory cleared.
* **spectral** = T: spectral adaptive penalties (Xu, Figueiredo and Goldstein 2017), each split's penalty
  re-estimated every T iterations from the curvatures its steps and duals show (:class:`Spectral`); a change costs
  the c-step's new pivots and the scaled duals' rescaling (:func:`change_penalties`), no factorisation.
"""
from __future__ import annotations

import math
from contextlib import contextmanager
from dataclasses import replace

import numpy as np

CORRELATION = 0.2         # the spectral penalties' safeguard: an estimate whose pair correlates less is not used
# the state's arrays after the splits (the host's: Ŷ for x − ξ over the field, the window's change in hv)
LINEAR_IN_SPLITS = ("x", "w", "s", "eta", "xi", "rho", "hv", "rest", "data_spectrum")


def split_variables(split, state) -> tuple[list, list]:
    """(z, y) on the data, TV and non-negativity splits, new arrays, from the state after the splits: z = (x,
    u_d = s_d + η_d, w), y = (ξ on the sensor window and 0 outside it, η_d, ρ)."""
    h, w = split.sensor_shape
    x = split.data_split(state)
    xi = np.zeros_like(x)
    xi[:, :h, :w] = state.xi
    return [x, state.s + state.eta, state.w.copy()], [xi, state.eta.copy(), state.rho.copy()]


def split_inputs(split, state) -> list[np.ndarray]:
    """q = z + y on the data, TV and non-negativity splits, from the state after the splits."""
    return [z + y for z, y in zip(*split_variables(split, state))]


def set_split_inputs(split, state, q: list[np.ndarray]) -> None:
    """The state the splits leave from the inputs ``q``: each prox and dual, and what the c-step reads (x − ξ,
    μ₃(w − ρ) in ``rest``, s_d = u_d − η_d)."""
    h, w = split.sensor_shape
    data, tv, nonneg = q
    misfit = split.b - np.einsum("khw,khw->hw", split.filters, data[:, :h, :w])
    xi = split._gain * -misfit
    x = data.copy()
    x[:, :h, :w] -= xi
    split.set_data_split(state, x, xi)
    for i, axis in enumerate(split.axes):
        bound = split.threshold(axis)
        np.clip(tv[i], -bound, bound, out=state.eta[i])
        np.subtract(tv[i], 2 * state.eta[i], out=state.s[i])
    np.maximum(nonneg - split.nonneg_shift(), 0, out=state.w)
    np.subtract(nonneg, state.w, out=state.rho)
    np.multiply(split.penalties.nonneg, state.w - state.rho, out=state.rest)


def inner(a: np.ndarray, b: np.ndarray) -> float:
    """⟨a, b⟩ of two real arrays, accumulated in float64."""
    return float(np.dot(a.ravel().astype(np.float64), b.ravel().astype(np.float64)))


def split_penalties(split) -> list:
    """Each split's penalty, broadcast against its variables: μ₁, μ₂,d (one per active TV axis, shaped to the
    stacked η_d), μ₃."""
    p = split.penalties
    return [p.data, np.array([p.tv_along(axis) for axis in split.axes]).reshape(-1, 1, 1, 1), p.nonneg]


def weighted_dot(split, a: list, b: list) -> float:
    """Σ_j μ_j⟨a_j, b_j⟩ over the three splits (the TV split's axis by axis)."""
    data, tv, nonneg = split_penalties(split)
    return (data * inner(a[0], b[0]) + sum(float(mu) * inner(x, y) for mu, x, y in zip(tv.ravel(), a[1], b[1]))
            + nonneg * inner(a[2], b[2]))


def anderson_point(g: list, f: list, dot) -> list:
    """The type-II Anderson point from the history of maps g_i = T(q_i) and residuals f_i (oldest first, the last is
    the newest): g_k − Σ_j γ_j(g_{j+1} − g_j), γ the least-squares fit of f_k by the residuals' differences (normal
    equations, a 1e-10 relative ridge). Each entry is a list of arrays; ``dot`` their inner product."""
    newest, n = g[-1], len(f) - 1
    if n == 0:
        return newest
    diff = lambda h, j: [a - b for a, b in zip(h[j + 1], h[j])]
    df = [diff(f, j) for j in range(n)]
    gram = np.array([[dot(df[i], df[j]) for j in range(n)] for i in range(n)])
    gamma = np.linalg.solve(gram + 1e-10 * np.trace(gram) * np.eye(n), [dot(d, f[-1]) for d in df])
    point = [a.copy() for a in newest]
    for j in range(n):
        for part, step in zip(point, diff(g, j)):
            part -= part.dtype.type(gamma[j]) * step
    return point


class Momentum:
    """Fast ADMM with restart (the module docstring), one per solve; ``events`` counts the restarts."""

    def __init__(self, eta: float, events: dict):
        self.eta, self.events = eta, events
        self.previous, self.residual, self.a = None, None, 1.0

    def __call__(self, split, plain_iterate, state):
        """One iteration: the c-step, the splits (their inputs' residual against the extrapolated point), then the
        next extrapolated point or the restart (``plain_iterate`` is not used: the residual needs the splits' inputs
        in between)."""
        hat = split_variables(split, state)          # (ẑ, ŷ), before the c-step relaxes the host's x − ξ
        split.c_step(state)
        result = split.splits(state, split.relaxation)
        residual = self.combined_residual(split, split_variables(split, state), hat)
        current = {n: getattr(state, n).copy() for n in LINEAR_IN_SPLITS}
        if self.previous is not None and residual >= self.eta * self.residual:
            for n in LINEAR_IN_SPLITS:
                getattr(state, n)[...] = self.previous[n]
            self.a, self.residual = 1.0, self.residual / self.eta
            self.events["restarts"] += 1
        elif self.previous is not None:
            a = (1 + np.sqrt(1 + 4 * self.a ** 2)) / 2
            for n in LINEAR_IN_SPLITS:
                array = getattr(state, n)
                array += array.dtype.type((self.a - 1) / a) * (array - self.previous[n])
            self.a, self.residual = a, residual
        else:
            self.residual = residual
        self.previous = current
        return result

    @staticmethod
    def combined_residual(split, now: tuple, hat: tuple) -> float:
        """Σ μ(‖z − ẑ‖² + ‖y − ŷ‖²) from the (z, y) of :func:`split_variables` after the splits and before them."""
        (z, y), (z_hat, y_hat) = now, hat
        dz, dy = [a - b for a, b in zip(z, z_hat)], [a - b for a, b in zip(y, y_hat)]
        return weighted_dot(split, dz, dz) + weighted_dot(split, dy, dy)


class Anderson:
    """Anderson-accelerated ADMM (the module docstring), one per solve; ``events`` counts the dropped points."""

    def __init__(self, memory: float, events: dict):
        self.memory, self.events = int(memory), events
        self.point, self.plain, self.residual = None, None, None
        self.maps, self.residuals = [], []

    def __call__(self, split, plain_iterate, state):
        """One plain iteration from the current point, then the next Anderson point or the safeguard's fallback."""
        q = split_inputs(split, state) if self.point is None else self.point
        result = plain_iterate(split, state)
        g = split_inputs(split, state)
        f = [a - b for a, b in zip(g, q)]
        residual = weighted_dot(split, f, f)
        if self.plain is not None and residual >= self.residual:
            self.events["restarts"] += 1
            self.point, self.plain, self.maps, self.residuals = self.plain, None, [], []
            set_split_inputs(split, state, self.point)
            return result
        self.residual = residual
        self.maps = (self.maps + [g])[-(self.memory + 1):]
        self.residuals = (self.residuals + [f])[-(self.memory + 1):]
        self.point = anderson_point(self.maps, self.residuals, lambda a, b: weighted_dot(split, a, b))
        self.plain = g if len(self.maps) > 1 else None
        if self.plain is not None:
            set_split_inputs(split, state, self.point)
        return result


def spectral_estimate(step: np.ndarray, dual_step: np.ndarray) -> tuple[float | None, float]:
    """Xu, Figueiredo and Goldstein's hybrid spectral estimate of a penalty from one pair (a step of an operator's
    image or of a split, and of the dual it is paired with, monotone): with a = ⟨Δλ,Δλ⟩/⟨Δx,Δλ⟩ (steepest descent)
    and m = ⟨Δx,Δλ⟩/⟨Δx,Δx⟩ (minimum gradient), m if 2m > a else a − m/2; and the pair's correlation. None where
    the pair is not monotone."""
    cross, steps, duals = inner(step, dual_step), inner(step, step), inner(dual_step, dual_step)
    if cross <= 0 or steps == 0 or duals == 0:
        return None, 0.0
    descent, gradient = duals / cross, cross / steps
    return (gradient if 2 * gradient > descent else descent - gradient / 2), cross / np.sqrt(steps * duals)


def spectral_penalty(penalty: float, first: tuple, second: tuple) -> float:
    """The new penalty from the c-step's estimate ``first`` and the split's ``second`` ((estimate, correlation)
    each): their geometric mean where both correlate, the one that does, else the penalty as it was."""
    usable = [estimate for estimate, correlation in (first, second)
              if estimate is not None and correlation > CORRELATION]
    return float(np.sqrt(np.prod(usable))) if len(usable) == 2 else (usable[0] if usable else penalty)


def split_images(split, state) -> list[np.ndarray]:
    """K v on each split (Hv, D_d v per TV axis, v), after the c-step (Hv by a convolution of v: the host keeps no
    Hv over the field)."""
    from clsdcam.algorithms.admm.host_steps import difference

    tv = np.stack([difference(state.v, axis, np.empty_like(state.v)) for axis in split.axes]) if split.axes else None
    return [split.convolve(state.v).astype(split.dtype), tv, state.v.copy()]


def change_penalties(split, state, penalties) -> None:
    """New penalties for the state the splits left: the splits z stay, the scaled duals y scale by μ/μ' (the
    unscaled duals μy stay), and every derived array follows (:func:`set_split_inputs`)."""
    old = split_penalties(split)
    z, y = split_variables(split, state)
    split.set_penalties(penalties)
    state.penalties = penalties
    ratios = [mu / new for mu, new in zip(old, split_penalties(split))]
    set_split_inputs(split, state, [a + b * np.asarray(r, np.float32) for a, b, r in zip(z, y, ratios)])


class Spectral:
    """Spectral adaptive penalties (Xu, Figueiredo and Goldstein 2017, AADMM), one per split: every ``period``
    iterations, with the intermediate dual λ̂ = μ(y_old + Kv − z_old) (unrelaxed: the c-step's optimality is
    Σ_j K_jᵀλ̂_j = 0 whatever α, as in Xu et al.'s relaxed AADMM) and λ = μy, the c-step's estimate from
    (Δ(Kv), −Δλ̂) and the split's from (Δz, Δλ) (:func:`spectral_estimate`; λ's sign is the opposite of theirs),
    combined by :func:`spectral_penalty`. ``events`` counts the penalty changes. Here the c-step has no term of its
    own (every term is in a split), so the c-step's estimates can only be read split by split, and since
    Σ_j K_jᵀλ̂_j = 0 their cross terms sum to zero: at least one split's is never monotone, and those that pass read
    the splits' coupling rather than a term's curvature."""

    def __init__(self, period: float, events: dict):
        self.period, self.events = int(period), events
        self.iteration, self.anchor = 0, None

    def __call__(self, split, plain_iterate, state):
        """One iteration, its pairs recorded; every ``period`` iterations the penalties estimated and changed."""
        z_old, y_old = split_variables(split, state)
        split.c_step(state)
        images = split_images(split, state)
        result = split.splits(state, split.relaxation)
        z, y = split_variables(split, state)
        mus = split_penalties(split)
        now = {"image": images, "z": z, "dual": [mu * b for mu, b in zip(mus, y)],
               "hat": [mu * (b + k - a) for mu, k, a, b in zip(mus, images, z_old, y_old)]}
        self.iteration += 1
        if self.anchor is not None and self.iteration % self.period == 0:
            self.adapt(split, state, now)
        if self.anchor is None or self.iteration % self.period == 0:
            self.anchor = now
        return result

    def adapt(self, split, state, now: dict) -> None:
        p, a = split.penalties, self.anchor
        new = []
        for j, mu in enumerate((p.data, p.tv, p.nonneg)):
            if now["image"][j] is None:
                new.append(mu)
                continue
            first = spectral_estimate(now["image"][j] - a["image"][j], a["hat"][j] - now["hat"][j])
            second = spectral_estimate(now["z"][j] - a["z"][j], now["dual"][j] - a["dual"][j])
            new.append(spectral_penalty(mu, first, second))
        if new != [p.data, p.tv, p.nonneg]:
            self.events["restarts"] += 1
            change_penalties(split, state, replace(p, data=new[0], tv=new[1], nonneg=new[2], tv_balance=None))


@contextmanager
def accelerated(variant: dict):
    """ADMM's host iteration wrapped by the acceleration ``variant`` names (none: as built), restored after; yields
    the events (restarts or dropped points) it counts. An accelerated ADMM runs without the TV penalties' balance
    (``clsdcam.algorithms.admm.balance``): the accelerations were measured before it, and their memories of past
    splits and duals would mix two penalties' scales."""
    from clsdcam.algorithms.admm import algorithm
    from clsdcam.algorithms.admm.terms import SplittingBase

    events = {"restarts": 0}
    plain = SplittingBase.iterate
    named = [name for name in ACCELERATIONS if name in variant]
    if not named:
        yield events
        return
    factory, value = ACCELERATIONS[named[0]], variant[named[0]]

    def iterate(split, state):
        if "_acceleration" not in split.__dict__:      # one per solve: each solve builds its own steps
            split._acceleration = factory(value, events)
        return split._acceleration(split, plain, state)

    balance_at = algorithm.BALANCE_AT
    SplittingBase.iterate, algorithm.BALANCE_AT = iterate, math.inf
    try:
        yield events
    finally:
        SplittingBase.iterate, algorithm.BALANCE_AT = plain, balance_at


ACCELERATIONS = {"momentum": Momentum, "anderson": Anderson, "spectral": Spectral}   # the variant names it reads
