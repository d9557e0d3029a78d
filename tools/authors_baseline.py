"""The authors' published solver (Monakhova et al. 2020, ``fista_spectral_numpy``), re-written
from its description as the speed and accuracy baseline of ``tools/bench_recon.py``.

What it does, as published:
- cube (2H, 2W, K) float64 on the 2×-padded field; A and Aᵀ through complex128 ``fft2`` /
  ``ifft2`` of the whole padded cube, every band, every iteration (no real FFTs, no reuse);
- step 1/L with L = 45·λ, λ from 10 power iterations of x ↦ pad(Σ_k F_k ⊙ crop(h ∗ x))
  on a random 2-D field;
- prox(x) = ½·(max(x, 0) + HaarTV(x)), the average of non-negativity and a 3-D TV step by
  shifted 1-level Haar transforms with periodic boundaries (np.roll), threshold
  3·2√2·τ/L on x and y and α times that on λ (τ = α = 5·10⁻⁵);
- momentum t⁺ = 1 + √(1 + 4t²)/2 (sic: the published code's precedence), v⁺ = x⁺ + (t − 1)/t⁺·(x⁺ − x).
Only the calibration geometry is ours (PSF origin at the frame centre), so its cube is
directly comparable with clsdcam's.
"""
from __future__ import annotations

import numpy as np

TAU = 5e-5
ALPHA = 5e-5


class AuthorsSolver:
    """One calibration; :meth:`run` yields (iteration, sensor-window cube (K, H, W)) after each step."""

    def __init__(self, psf: np.ndarray, filters: np.ndarray, seed: int = 0):
        if filters.shape[0] % 2:
            raise ValueError(f"{filters.shape[0]} bands: the published Haar TV needs an even band count")
        self.h, self.w = psf.shape
        self.mask = np.moveaxis(filters, 0, -1).astype(np.float64)  # (H, W, K) as published
        self.py, self.px = self.h // 2, self.w // 2
        field = self.pad(psf.astype(np.float64))
        self.transfer = np.fft.fft2(np.fft.ifftshift(field, axes=(0, 1)), axes=(0, 1))[..., None]
        self.lipschitz = 45.0 * self.power_iteration(np.random.default_rng(seed))

    def pad(self, x):
        widths = [(self.py, self.py), (self.px, self.px)] + [(0, 0)] * (x.ndim - 2)
        return np.pad(x, widths)

    def crop(self, x):
        return x[self.py:self.py + self.h, self.px:self.px + self.w]

    def forward(self, x):
        """b = Σ_k F_k ⊙ crop(Re ifft2(Ĥ · fft2(x_k)))."""
        convolved = np.real(np.fft.ifft2(self.transfer * np.fft.fft2(x, axes=(0, 1)), axes=(0, 1)))
        return np.sum(self.mask * self.crop(convolved), axis=2)

    def adjoint(self, r):
        """Aᵀr = Re ifft2(conj Ĥ · fft2(pad(F_k ⊙ r)))."""
        spread = self.pad(r[..., None] * self.mask)
        return np.real(np.fft.ifft2(np.conj(self.transfer) * np.fft.fft2(spread, axes=(0, 1)), axes=(0, 1)))

    def power_iteration(self, rng, iters: int = 10) -> float:
        """λ of x ↦ pad(A x) for a 2-D x broadcast over bands, as published."""
        x = rng.standard_normal((2 * self.h, 2 * self.w))
        for _ in range(iters):
            y = self.pad(self.forward(np.repeat(x[..., None], self.mask.shape[2], axis=2)))
            x = y / np.linalg.norm(y)
        y = self.pad(self.forward(np.repeat(x[..., None], self.mask.shape[2], axis=2)))
        return float(np.vdot(x, y) / np.vdot(x, x))

    def prox(self, x):
        return 0.5 * (np.maximum(x, 0) + haar_tv_periodic(x, TAU / self.lipschitz, ALPHA))

    def run(self, measurement: np.ndarray, iters: int):
        """Yield (k, cube (K, H, W) float32) after each of ``iters`` iterations."""
        b = np.asarray(measurement, np.float64)
        x = np.zeros((2 * self.h, 2 * self.w, self.mask.shape[2]))
        v, t = x.copy(), 1.0
        for k in range(1, iters + 1):
            x_new = self.prox(v - self.adjoint(self.forward(v) - b) / self.lipschitz)
            t_new = 1 + np.sqrt(1 + 4 * t ** 2) / 2
            v = x_new + (t - 1) / t_new * (x_new - x)
            x, t = x_new, t_new
            yield k, np.moveaxis(self.crop(x), -1, 0).astype(np.float32)


def haar_tv_periodic(x, tau: float, alpha: float):
    """Mean over the 3 axes and 2 shifts of the 1-level Haar transform with its detail soft-thresholded
    (threshold 3·2√2·τ, times α on the band axis); periodic boundaries. Axes of even length."""
    threshold = 3 * 2 * np.sqrt(2) * tau
    out = np.zeros_like(x)
    for axis in range(3):
        t = threshold * (alpha if axis == 2 else 1.0)
        for shift in (0, 1):
            rolled = np.roll(x, -shift, axis=axis)
            even, odd = _halves(rolled, axis)
            mean, detail = (even + odd) / np.sqrt(2), (odd - even) / np.sqrt(2)
            detail = np.sign(detail) * np.maximum(np.abs(detail) - t, 0)
            back = np.empty_like(x)
            _set_halves(back, axis, (mean - detail) / np.sqrt(2), (mean + detail) / np.sqrt(2))
            out += np.roll(back, shift, axis=axis)
    return out / 6


def _halves(x, axis):
    index = [slice(None)] * 3
    index[axis] = slice(0, None, 2)
    even = x[tuple(index)]
    index[axis] = slice(1, None, 2)
    return even, x[tuple(index)]


def _set_halves(out, axis, even, odd):
    index = [slice(None)] * 3
    index[axis] = slice(0, None, 2)
    out[tuple(index)] = even
    index[axis] = slice(1, None, 2)
    out[tuple(index)] = odd
