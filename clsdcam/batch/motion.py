"""Motion prediction for warm starts: the drift between two cubes by phase correlation.

A scene moving at constant velocity shows in x̂_{i−1} moved by the drift d seen between
x̂_{i−2} and x̂_{i−1}; so frame i starts from x̂_{i−1} shifted by d. With s = Σ_k x̂_k the band
sums, the phase correlation

    c = ℱ⁻¹[ℱs_{i−1}·conj(ℱs_{i−2}) / |ℱs_{i−1}·conj(ℱs_{i−2})|]

peaks at d (a translation is a phase ramp); a parabola through the peak and its two
neighbours on each axis refines it to sub-pixel, p + ½(c₋ − c₊)/(c₋ − 2c₀ + c₊).
"""
from __future__ import annotations

import numpy as np


def predict(before, previous, min_shift: float = 0.05):
    """Warm start for frame i from x̂_{i−2} (``before``) and x̂_{i−1} (``previous``), assuming constant velocity.

    The drift d is the peak of the phase correlation of the band sums s = Σ_k x̂_k,
    c = ℱ⁻¹[ℱs_{i−1}·conj(ℱs_{i−2}) / |ℱs_{i−1}·conj(ℱs_{i−2})|], refined to sub-pixel by a parabola
    through the peak and its two neighbours on each axis; x0 = x̂_{i−1} shifted by d (bilinear,
    zero fill, clipped at 0). Without ``before``, or for |d| < ``min_shift`` px, x0 = x̂_{i−1}.
    """
    if previous is None or before is None:
        return previous
    import scipy.ndimage as ndi

    drift = _drift(before, previous)
    if np.hypot(*drift) < min_shift:
        return previous
    return np.maximum(ndi.shift(previous, (0, *drift), order=1), 0).astype(np.float32)


def _drift(before, previous) -> list[float]:
    """(dy, dx) in px, each in (−n/2, n/2]: the sub-pixel peak of the band sums' phase correlation."""
    cross = np.fft.fft2(previous.sum(0)) * np.conj(np.fft.fft2(before.sum(0)))
    c = np.fft.ifft2(cross / np.maximum(np.abs(cross), 1e-12 * np.abs(cross).max())).real
    peak = np.unravel_index(np.argmax(c), c.shape)
    drift = []
    for axis, n in enumerate(c.shape):
        lo, mid, hi = (c[tuple((p + (k if a == axis else 0)) % c.shape[a] for a, p in enumerate(peak))] for k in (-1, 0, 1))
        d = peak[axis] + (0.5 * (lo - hi) / (lo - 2 * mid + hi) if lo - 2 * mid + hi else 0.0)
        drift.append(d - n if d > n / 2 else d)
    return drift
