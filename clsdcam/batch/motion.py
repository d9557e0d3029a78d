"""Motion prediction for warm starts: the drift between two cubes, and the next frame's start moved by it.

A scene moving at constant velocity shows in x̂_{i−1} moved by the drift d seen between x̂_{i−2} and
x̂_{i−1}; so frame i starts from frame i−1's solution shifted by d. The drift is read from the band sums
s = Σ_k x̂_k by phase correlation, c = ℱ⁻¹[ℱs_{i−1}·conj(ℱs_{i−2}) / |ℱs_{i−1}·conj(ℱs_{i−2})|], whose peak
is at d (a translation is a phase ramp), to 1/UPSAMPLE px by the matrix-multiply DFT upsampling of
Guizar-Sicairos et al. (Opt. Lett. 2008) — scikit-image's ``phase_cross_correlation``. The shift itself is a
phase ramp too, x(p − d) = ℱ⁻¹[ℱx · e^{−2πi⟨f, d⟩}] (``scipy.ndimage.fourier_shift``): exact for any
sub-pixel d on band-limited content, where bilinear interpolation would blur the start by up to half a pixel
(and barely move it: a 0.6 px drift read to ±0.5 px by a parabola through the correlation peak is lost in
that blur). The transform is periodic: content leaving one side enters the other, which the solver's field
(zero-padded to twice the sensor) keeps away from the sensor window; negative ringing is clipped at 0.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

UPSAMPLE = 50        # the drift is read to 1/UPSAMPLE px
MIN_SHIFT = 0.05     # px: below this the start is not moved


def drift(before: np.ndarray, previous: np.ndarray) -> tuple[float, float]:
    """(dy, dx) in px: the translation that takes the band sums of ``before`` (K, H, W) to ``previous``'s."""
    from skimage.registration import phase_cross_correlation

    shift, _, _ = phase_cross_correlation(np.sum(previous, axis=0, dtype=np.float64),
                                          np.sum(before, axis=0, dtype=np.float64),
                                          upsample_factor=UPSAMPLE, normalization="phase")
    return float(shift[0]), float(shift[1])


def phase_shift(planes: np.ndarray, d: tuple[float, float]) -> np.ndarray:
    """``planes`` (N, H, W) moved by d = (dy, dx) px: ℱ⁻¹[ℱx · e^{−2πi⟨f, d⟩}] per plane (float32)."""
    import scipy.fft
    import scipy.ndimage as ndi

    h, w = planes.shape[-2:]
    spectrum = scipy.fft.rfft2(np.asarray(planes, np.float32), workers=-1)
    return scipy.fft.irfft2(ndi.fourier_shift(spectrum, (0, *d), n=w), s=(h, w), workers=-1).astype(np.float32)


def shifted(cube: np.ndarray, d: tuple[float, float]) -> np.ndarray:
    """A non-negative ``cube`` (K, H, W) moved by d px, its ringing clipped at 0."""
    return np.maximum(phase_shift(cube, d), 0)


def significant_drift(before, previous, min_shift: float) -> tuple[float, float] | None:
    """The drift from ``before`` to ``previous``; None when either is unknown or it is under ``min_shift`` px."""
    if before is None or previous is None:
        return None
    d = drift(before, previous)
    return None if np.hypot(*d) < min_shift else d


def predict(before, previous, min_shift: float = MIN_SHIFT):
    """Warm start for frame i from x̂_{i−2} (``before``) and x̂_{i−1} (``previous``), assuming constant
    velocity: ``previous`` moved by their drift; ``previous`` itself without ``before`` or when the drift is
    under ``min_shift`` px."""
    d = significant_drift(before, previous, min_shift)
    return previous if d is None else shifted(previous, d)


def predict_state(before, previous, state, backend, min_shift: float = MIN_SHIFT):
    """A solver state (:class:`clsdcam.solve.state.SolverState`) for frame i: frame i−1's, its whole field moved by
    the drift between the cubes x̂_{i−2} (``before``) and x̂_{i−1} (``previous``), the algorithm's carry reduced to
    what survives the move (its ``moved()``: ADMM's penalties, not its duals, which belong to the unmoved field);
    as it is when the drift is unknown or under ``min_shift`` px."""
    d = significant_drift(before, previous, min_shift)
    if d is None:
        return state
    kept = None if state.carry is None else state.carry[0].moved()
    return replace(state, field=backend.to_device(moved_field(backend.to_host(state.field), state.basis, d)),
                   carry=None if kept is None else (kept, state.carry[1]))


def moved_field(field: np.ndarray, basis: np.ndarray | None, d: tuple[float, float]) -> np.ndarray:
    """``field`` (K, Hp, Wp) moved by d; with a spectral basis B (K × r, orthonormal), its coefficients
    c = Bᵀv are moved and expanded, B·shift(c): r planes transformed instead of K, and what the next solve
    starts from (it enters B at once, c = Bᵀ(B·shift(c)) = shift(c); no clipping, which would leave B)."""
    if basis is None:
        return shifted(field, d)
    k, hp, wp = field.shape
    coefficients = (basis.T @ field.reshape(k, -1)).reshape(-1, hp, wp)
    moved = phase_shift(coefficients, d)
    return (basis @ moved.reshape(moved.shape[0], -1)).reshape(k, hp, wp).astype(np.float32)
