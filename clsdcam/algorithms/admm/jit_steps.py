"""ADMM's host passes compiled by Numba (the ``jit`` extra): :class:`JitSplitting`, the NumPy steps
(:class:`~.host_steps.Splitting`) with their splits, TV adjoint and solve along λ written as loops over a block of
rows, in the arithmetic of ``kernels/admm.cl`` (the data split on the window, as host_steps keeps it); each loop walks
the block band by band, every plane's rows in order (the x-step, which first walked it row by row across the bands,
took 1.4–2× the time it takes now in a solve: docs/benchmarks.md, "The x-step band by band").

NumPy makes one pass over the field per operation: its splits and TV adjoint read and write the cube several dozen
times an iteration, and took twice the time of its 4K transforms; here the w-step, the u-step along each axis and the
TV adjoint pass once each, the x-step twice over the window, its sums and then its step, and not at all outside it
(host_steps' module docstring; docs/convergence.md, "ADMM's passes compiled on the host"), and the solve along λ twice
over the spectra, its forward sweep and its back sweep with Ŷ's update (compiled alone, the sweeps took NumPy's time;
with Ŷ's update fused in, 0.68–0.75× what NumPy's solve took without it: docs/benchmarks.md, "ADMM's data split on the
window"). NumPy cannot fuse them, and numexpr, which fuses expressions, ran the u-step's arithmetic 4× slower than
NumPy's passes (docs/admm.md, "Seconds per iteration"); hence these loops, written by hand. They are the kernels'
arithmetic in the kernels' order (sums in float64, as the kernels' ``ACC``), and NumPy's but for the rounding of its
sums over the bands and of the solve's complex products (tests/test_admm.py). The blocks and threads are host_steps'
own: the loops release the GIL, so :func:`~clsdcam.backends.map_blocks` runs them on its threads, and Numba starts no
thread pool of its own (safe under Dask's threads). Compiled on first use and cached (beside the module, or in Numba's
own cache folder where that is not writable). The one-off passes (the duals rescaled for new penalties) stay NumPy's."""
from __future__ import annotations

import numpy as np
from numba import njit

from ...backends import map_blocks
from .host_steps import Splitting
from .terms import SplitState

COMPILE = {"nogil": True, "cache": True}


@njit(**COMPILE)
def window_misfit(y, x, xi, f, b, alpha, one_minus, two_minus, y0, y1):
    """The x-step's per-pixel sums on the window's rows y0…y1, band by band (each plane's rows read in order), from
    the relaxed y = α·Hv + (1 − α)·(x − ξ): the misfit b − fᵀq with q = y + (2 − α)·ξ (its sum over the bands in
    float64, then rounded to the cube's precision, as the kernel's REAL), and ½Σ(fᵀHv − b)² over those rows at
    Hv = (y − (1 − α)·(x − ξ))/α, before the step."""
    rows, w = y1 - y0, b.shape[1]
    fitted, stepped = np.zeros((rows, w)), np.zeros((rows, w))
    for k in range(y.shape[0]):
        for r in range(rows):
            row = y0 + r
            for c in range(w):
                fk, here, dual = f[k, row, c], y[k, row, c], xi[k, row, c]
                fitted[r, c] += np.float64(fk) * np.float64((here - one_minus * (x[k, row, c] - dual)) / alpha)
                stepped[r, c] += np.float64(fk) * np.float64(here + two_minus * dual)
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
def x_pass(y, x, xi, f, gain, b, alpha, one_minus, two_minus, y0, y1):
    """The x-step on the window's rows y0…y1 (``y``, ``x`` and ``xi`` the window's; host_steps' module docstring):
    from y = α·Hv + (1 − α)·(x − ξ), q = y + (2 − α)·ξ, ξ⁺ = −g·(b − fᵀq), x ← q − ξ⁺, y ← (2 − α)·ξ − 2ξ⁺, ξ ← ξ⁺,
    per element the arithmetic of ``kernels/admm.cl``'s admm_x_step from its q on. Returns ½Σ(fᵀHv − b)² over those
    rows, at Hv before the step. Band by band (row by row across the bands, the pass took about 2× the time in a
    solve at 128×160 and 1.4–1.6× at 320×448)."""
    data, misfit = window_misfit(y, x, xi, f, b, alpha, one_minus, two_minus, y0, y1)
    for k in range(y.shape[0]):
        for row in range(y0, y1):
            for c in range(b.shape[1]):
                old = xi[k, row, c]
                q = y[k, row, c] + two_minus * old
                e = -gain[k, row, c] * misfit[row - y0, c]
                x[k, row, c] = q - e
                y[k, row, c] = two_minus * old - (e + e)
                xi[k, row, c] = e
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


@njit(**COMPILE)
def band_pass(data, change, rest, data_transfer, transfer, pivots, coupling, alpha, one_minus, y0, y1):
    """The c-step's solve along λ on spectrum rows y0…y1 (host_steps' ``_band_solve``, in its arithmetic): Ŷ ←
    Ŷ + change; Thomas's forward sweep on r_j = rest_j + μ₁conj(Ĥ)·Ŷ_j, g_j = (r_j + e·g_{j−1})·m_j, then the back
    sweep v̂_j = g_j + (e·m_j)·v̂_{j+1} into ``rest``, each band's Ŷ ← α·Ĥv̂_j + (1 − α)·Ŷ_j once its v̂_j is final,
    and copied into ``change``. Two passes over the block's planes where NumPy's operations make a dozen; the tests on
    the band, the coupling and α made once a row, outside the loops along x."""
    n_bands, cols = data.shape[0], data.shape[2]
    for j in range(n_bands):
        coupled = j > 0 and coupling != 0
        for y in range(y0, y1):
            if coupled:
                for c in range(cols):
                    kept = data[j, y, c] + change[j, y, c]
                    data[j, y, c] = kept
                    g = rest[j, y, c] + kept * data_transfer[y, c]
                    rest[j, y, c] = (g + rest[j - 1, y, c] * coupling) * pivots[j, y, c]
            else:
                for c in range(cols):
                    kept = data[j, y, c] + change[j, y, c]
                    data[j, y, c] = kept
                    rest[j, y, c] = (rest[j, y, c] + kept * data_transfer[y, c]) * pivots[j, y, c]
    for j in range(n_bands - 1, -1, -1):
        coupled = j + 1 < n_bands and coupling != 0
        for y in range(y0, y1):
            if coupled:
                for c in range(cols):
                    rest[j, y, c] = rest[j, y, c] + rest[j + 1, y, c] * (pivots[j, y, c] * coupling)
            if alpha == 1:
                for c in range(cols):
                    data[j, y, c] = change[j, y, c] = rest[j, y, c] * transfer[y, c]
            else:
                for c in range(cols):
                    hv = rest[j, y, c] * transfer[y, c]
                    data[j, y, c] = change[j, y, c] = data[j, y, c] * one_minus + hv * alpha


class JitSplitting(Splitting):
    """:class:`~.host_steps.Splitting` with its passes on each row block compiled (the module docstring)."""

    def _split_block(self, state: SplitState, y0: int, y1: int, scratch: dict, alpha: float):
        a, one_minus, two_minus = self._scalars(alpha)
        real = self.dtype.type
        h = self.sensor_shape[0]
        data = x_pass(state.hv, state.x, state.xi, self.filters, self._gain, self.b, a, one_minus, two_minus, y0,
                      min(y1, h)) if y0 < h else 0.0
        step, norm = w_pass(state.v, state.w, state.rho, state.rest, real(self.nonneg_shift()),
                            real(self.penalties.nonneg), a, one_minus, real(0), y0, y1)
        for i, axis in enumerate(self.axes):
            u_pass(state.v, state.eta[i], state.s[i], axis, real(self.threshold(axis)), a, one_minus, two_minus,
                   real(0), y0, y1)
        return data, step, norm

    def _band_solve(self, data: np.ndarray, change: np.ndarray, rest: np.ndarray) -> None:
        (k, rows, cols), coupling = data.shape, self.dtype.type(self.coupling)
        alpha, one_minus, _ = self._scalars(self.relaxation)
        map_blocks(lambda y0, y1, scratch: band_pass(data, change, rest, self._data_transfer, self.transfer,
                                                     self._pivots, coupling, alpha, one_minus, y0, y1),
                   rows, k * cols * data.itemsize, self.workers)

    def _adjoint_block(self, state: SplitState, y0: int, y1: int, scratch: dict) -> None:
        penalties = np.array([self.penalties.tv_along(axis) for axis in self.axes], self.dtype)
        adjoint_pass(state.rest, state.s, np.array(self.axes, np.int64), penalties, y0, y1)
