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

``AuthorsReplay`` runs the same iteration (same L, prox and momentum) in float32 with real-to-complex
transforms on every core: the same trajectory to float32 rounding, several times sooner. It is for
the authors' *error curve* at sizes where 500 published iterations take hours; their *time* still
comes from timing the published code (``bench_recon.py --authors-timed``).
"""
from __future__ import annotations

import math

import numpy as np
import scipy.fft

TAU = 5e-5
ALPHA = 5e-5
SQRT2 = math.sqrt(2)     # Python floats keep a float32 cube float32 (NumPy scalars would widen it)


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

    def convolve(self, x, transfer):
        """Re ifft2(transfer · fft2(x_k)) per band, as published (complex128, whole spectra)."""
        return np.real(np.fft.ifft2(transfer * np.fft.fft2(x, axes=(0, 1)), axes=(0, 1)))

    def forward(self, x):
        """b = Σ_k F_k ⊙ crop(Re ifft2(Ĥ · fft2(x_k)))."""
        return np.sum(self.mask * self.crop(self.convolve(x, self.transfer)), axis=2)

    def adjoint(self, r):
        """Aᵀr = Re ifft2(conj Ĥ · fft2(pad(F_k ⊙ r)))."""
        return self.convolve(self.pad(r[..., None] * self.mask), np.conj(self.transfer))

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
        b = np.asarray(measurement, self.mask.dtype)
        x = np.zeros((2 * self.h, 2 * self.w, self.mask.shape[2]), self.mask.dtype)
        v, t = x.copy(), 1.0
        for k in range(1, iters + 1):
            x_new = self.prox(v - self.adjoint(self.forward(v) - b) / self.lipschitz)
            t_new = 1 + math.sqrt(1 + 4 * t ** 2) / 2
            v = x_new + (t - 1) / t_new * (x_new - x)
            x, t = x_new, t_new
            yield k, np.moveaxis(self.crop(x), -1, 0).astype(np.float32)


class AuthorsReplay(AuthorsSolver):
    """The published iteration in float32 with real FFTs on every core (see the module docstring), with the
    published solver's geometry and L (its float64 power iteration)."""

    def __init__(self, published: AuthorsSolver):     # pylint: disable=super-init-not-called
        self.h, self.w, self.py, self.px = published.h, published.w, published.py, published.px
        self.lipschitz = published.lipschitz
        self.mask = published.mask.astype(np.float32)
        self.transfer = published.transfer[:, : self.w + 1].astype(np.complex64)   # rfft2's half of Ĥ (2W columns)

    def convolve(self, x, transfer):
        """irfft2(transfer · rfft2(x_k)): the published Re ifft2(Ĥ · fft2(x_k)) of a real x, in float32."""
        spectrum = scipy.fft.rfft2(x, axes=(0, 1), workers=-1)
        return scipy.fft.irfft2(transfer * spectrum, s=x.shape[:2], axes=(0, 1), workers=-1)


def haar_tv_periodic(x, tau: float, alpha: float):
    """Mean over the 3 axes and 2 shifts of the 1-level Haar transform with its detail soft-thresholded
    (threshold 3·2√2·τ, times α on the band axis); periodic boundaries. Axes of even length."""
    threshold = 3 * 2 * SQRT2 * tau
    out = np.zeros_like(x)
    for axis in range(3):
        t = threshold * (alpha if axis == 2 else 1.0)
        for shift in (0, 1):
            rolled = np.roll(x, -shift, axis=axis)
            even, odd = _halves(rolled, axis)
            mean, detail = (even + odd) / SQRT2, (odd - even) / SQRT2
            detail = np.sign(detail) * np.maximum(np.abs(detail) - t, 0)
            back = np.empty_like(x)
            _set_halves(back, axis, (mean - detail) / SQRT2, (mean + detail) / SQRT2)
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
