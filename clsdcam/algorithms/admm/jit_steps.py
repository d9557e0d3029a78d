"""ADMM's host passes compiled by Numba (the ``jit`` extra): :class:`JitSplitting`, the NumPy steps
(:class:`~.host_steps.Splitting`) with their splits and TV adjoint written as loops over a block of rows, in the
arithmetic of ``kernels/admm.cl``; each loop walks the block band by band, every plane's rows in order (the x-step,
which first walked it row by row across the bands, took 1.4–2× the time it takes now in a solve: docs/benchmarks.md,
"The x-step band by band").

NumPy makes one pass over the field per operation: its splits and TV adjoint read and write the cube several dozen
times an iteration, and took twice the time of its 4K transforms; here the w-step, the u-step along each axis and the
TV adjoint pass once each, the x-step twice over the window (its sums, then its step) and once elsewhere
(docs/convergence.md, "ADMM's passes compiled on the host"). NumPy cannot fuse them, and numexpr, which fuses
expressions, ran the u-step's arithmetic 4× slower than NumPy's passes (docs/admm.md, "Seconds per iteration"); hence
these loops, written by hand. They are the kernels' arithmetic in the kernels' order (sums in float64, as the kernels'
``ACC``), and NumPy's but for its sums' rounding. The blocks and threads are host_steps' own: the loops release the
GIL, so :func:`~clsdcam.backends.map_blocks` runs them on its threads, and Numba starts no thread pool of its own
(safe under Dask's threads). Compiled on first use and cached (beside the module, or in Numba's own cache folder where
that is not writable). The solve along λ stays NumPy's (compiled, it took the same time), and so do the one-off passes
(the duals rescaled for new penalties)."""
from __future__ import annotations

import numpy as np
from numba import njit

from .host_steps import Splitting
from .terms import SplitState

COMPILE = {"nogil": True, "cache": True}


@njit(**COMPILE)
def window_misfit(hv, x, xi, f, b, alpha, one_minus, y0, y1):
    """The x-step's per-pixel sums on the window's rows among y0…y1, band by band (each plane's rows read in order):
    the misfit b − fᵀq with q = α·hv + (1 − α)·x + ξ (its sum over the bands in float64, then rounded to the cube's
    precision, as the kernel's REAL), and ½Σ(fᵀhv − b)² over those rows, at hv before the step."""
    h, w = b.shape
    rows = max(min(y1, h) - y0, 0)
    fitted, stepped = np.zeros((rows, w)), np.zeros((rows, w))
    for k in range(hv.shape[0]):
        for r in range(rows):
            y = y0 + r
            for c in range(w):
                fk, here = f[k, y, c], hv[k, y, c]
                fitted[r, c] += np.float64(fk) * np.float64(here)
                stepped[r, c] += np.float64(fk) * np.float64(alpha * here + one_minus * x[k, y, c] + xi[k, y, c])
    data = 0.0
    misfit = np.empty((rows, w), b.dtype)
    for r in range(rows):
        for c in range(w):
            residual = fitted[r, c] - np.float64(b[y0 + r, c])
            data += 0.5 * residual * residual
            misfit[r, c] = stepped[r, c]
            misfit[r, c] = b[y0 + r, c] - misfit[r, c]
    return data, misfit


@njit(**COMPILE)
def x_pass(hv, x, xi, f, gain, b, alpha, one_minus, y0, y1):
    """The x-step on field rows y0…y1 (``kernels/admm.cl``'s admm_x_step): q = α·hv + (1 − α)·x (+ ξ on the window);
    on the window ξ ← −g·(b − fᵀq), x ← q − ξ, hv ← x − ξ; outside it x ← q, hv ← q. Returns ½Σ(fᵀhv − b)² over
    the block's window rows, at hv before the step. Band by band, each row's window and the rest of it in separate
    loops: per element the kernel's arithmetic, the planes read in order (row by row across the bands, the pass took
    about 2× the time in a solve at 128×160 and 1.4–1.6× at 320×448)."""
    n_bands, _, wp = hv.shape
    h, w = b.shape
    data, misfit = window_misfit(hv, x, xi, f, b, alpha, one_minus, y0, y1)
    for k in range(n_bands):
        for y in range(y0, y1):
            inside = w if y < h else 0
            for c in range(inside):
                q = alpha * hv[k, y, c] + one_minus * x[k, y, c] + xi[k, y, c]
                e = -gain[k, y, c] * misfit[y - y0, c]
                xi[k, y, c] = e
                q = q - e
                x[k, y, c] = q
                hv[k, y, c] = q - e
            for c in range(inside, wp):
                q = alpha * hv[k, y, c] + one_minus * x[k, y, c]
                x[k, y, c] = q
                hv[k, y, c] = q
    return data


@njit(**COMPILE)
def w_pass(v, w, rho, rest, shift, mu, alpha, one_minus, zero, y0, y1):
    """The w-step on rows y0…y1 (admm_w_step): q = α·v + (1 − α)·w + ρ, w⁺ = max(q − shift, 0) (NaN kept),
    ρ ← q − w⁺, rest ← μ₃(w⁺ − ρ); returns (‖w⁺ − w‖², ‖w⁺‖²) over the block, summed in float64 per column first
    (so that the loop along x vectorises). ``zero`` is in the cube's precision, as every scalar here: a literal
    would make the loop's values float64."""
    n_bands, _, wp = v.shape
    steps, norms = np.zeros(wp), np.zeros(wp)
    for k in range(n_bands):
        for y in range(y0, y1):
            for c in range(wp):
                q = alpha * v[k, y, c] + one_minus * w[k, y, c] + rho[k, y, c]
                z = q - shift
                z = zero if z < zero else z
                d = w[k, y, c] - z
                steps[c] += np.float64(d) * np.float64(d)
                norms[c] += np.float64(z) * np.float64(z)
                w[k, y, c] = z
                q = q - z
                rho[k, y, c] = q
                rest[k, y, c] = mu * (z - q)
    return steps.sum(), norms.sum()


@njit(**COMPILE)
def _u_point(step, eta, s, k, y, c, limit, alpha, one_minus, two_minus):
    """One element of the u-step from its difference ``step``; the clip as the kernels' clip_to (NaN kept)."""
    q = alpha * step + one_minus * s[k, y, c] + two_minus * eta[k, y, c]
    e = -limit if q < -limit else (limit if q > limit else q)
    eta[k, y, c] = e
    s[k, y, c] = (q - e) - e


@njit(**COMPILE)
def u_pass(v, eta, s, axis, limit, alpha, one_minus, two_minus, zero, y0, y1):
    """The u-step along ``axis`` on rows y0…y1 (admm_u_step): q = α·D_d v + (1 − α)·s_d + (2 − α)·η_d,
    η_d ← clip(q, ±limit), s_d ← (q − η_d) − η_d; D_d the forward difference (``zero`` at the last band, circular on
    y and x). The inner loops run along x with the neighbour's index fixed, so that they vectorise."""
    n_bands, hp, wp = v.shape
    for k in range(n_bands):
        for y in range(y0, y1):
            if axis == 2:
                for c in range(wp - 1):
                    _u_point(v[k, y, c + 1] - v[k, y, c], eta, s, k, y, c, limit, alpha, one_minus, two_minus)
                _u_point(v[k, y, 0] - v[k, y, wp - 1], eta, s, k, y, wp - 1, limit, alpha, one_minus, two_minus)
            elif axis == 0 and k + 1 == n_bands:
                for c in range(wp):
                    _u_point(zero, eta, s, k, y, c, limit, alpha, one_minus, two_minus)
            else:
                ahead_k, ahead_y = (k + 1, y) if axis == 0 else (k, y + 1 if y + 1 < hp else 0)
                for c in range(wp):
                    _u_point(v[ahead_k, ahead_y, c] - v[k, y, c], eta, s, k, y, c, limit, alpha, one_minus,
                             two_minus)


@njit(**COMPILE)
def adjoint_pass(rest, s, axes, penalties, y0, y1):
    """rest += Σ_d μ₂,d·D_dᵀs_d on rows y0…y1 (admm_tv_adjoint), (D_dᵀu)_i = u_{i−1} − u_i (along λ u_{−1} = 0 and
    u_{K−1} unused; circular on y and x); ``s`` holds one cube per entry of ``axes``, ``penalties`` their μ₂,d.
    Axis by axis over the block, each element's terms in the kernel's order."""
    n_bands, hp, wp = rest.shape
    for i in range(axes.size):
        mu, axis = penalties[i], axes[i]
        for k in range(n_bands):
            for y in range(y0, y1):
                if axis == 0:
                    if k + 1 < n_bands:
                        for c in range(wp):
                            rest[k, y, c] -= mu * s[i, k, y, c]
                    if k > 0:
                        for c in range(wp):
                            rest[k, y, c] += mu * s[i, k - 1, y, c]
                elif axis == 1:
                    above = y - 1 if y > 0 else hp - 1
                    for c in range(wp):
                        rest[k, y, c] = (rest[k, y, c] - mu * s[i, k, y, c]) + mu * s[i, k, above, c]
                else:
                    rest[k, y, 0] = (rest[k, y, 0] - mu * s[i, k, y, 0]) + mu * s[i, k, y, wp - 1]
                    for c in range(1, wp):
                        rest[k, y, c] = (rest[k, y, c] - mu * s[i, k, y, c]) + mu * s[i, k, y, c - 1]


class JitSplitting(Splitting):
    """:class:`~.host_steps.Splitting` with its passes on each row block compiled (the module docstring)."""

    def _scalars(self, alpha: float) -> tuple:
        """α, 1 − α and 2 − α rounded to the cube's precision as the kernels round them."""
        one, a = self.dtype.type(1), self.dtype.type(alpha)
        return a, one - a, self.dtype.type(2) - a

    def _split_block(self, state: SplitState, y0: int, y1: int, scratch: dict, alpha: float):
        a, one_minus, two_minus = self._scalars(alpha)
        real = self.dtype.type
        data = x_pass(state.hv, state.x, state.xi, self.filters, self._gain, self.b, a, one_minus, y0, y1)
        step, norm = w_pass(state.v, state.w, state.rho, state.rest, real(self.nonneg_shift()),
                            real(self.penalties.nonneg), a, one_minus, real(0), y0, y1)
        for i, axis in enumerate(self.axes):
            u_pass(state.v, state.eta[i], state.s[i], axis, real(self.threshold(axis)), a, one_minus, two_minus,
                   real(0), y0, y1)
        return data, step, norm

    def _adjoint_block(self, state: SplitState, y0: int, y1: int, scratch: dict) -> None:
        penalties = np.array([self.penalties.tv_along(axis) for axis in self.axes], self.dtype)
        adjoint_pass(state.rest, state.s, np.array(self.axes, np.int64), penalties, y0, y1)
