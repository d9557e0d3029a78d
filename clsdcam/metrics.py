"""Accuracy of a reconstructed cube against the truth."""
from __future__ import annotations

import numpy as np


def psnr(cube: np.ndarray, truth: np.ndarray) -> float:
    """PSNR in dB with the truth's peak: 10·log10(max(truth)² / mean((cube − truth)²))."""
    cube, truth = np.asarray(cube, np.float64), np.asarray(truth, np.float64)
    mse = np.mean((cube - truth) ** 2)
    peak = np.max(np.abs(truth))
    if mse == 0:
        return float("inf")
    return float(10 * np.log10(peak ** 2 / mse))


def spectral_angle(cube: np.ndarray, truth: np.ndarray, threshold: float = 0.05) -> float:
    """Mean angle (degrees) between recovered and true spectra, arccos(⟨s, ŝ⟩ / ‖s‖‖ŝ‖).

    Averaged over the pixels whose true spectrum has a norm above ``threshold`` times the
    largest one (dark pixels have no meaningful spectrum).
    """
    cube, truth = np.asarray(cube, np.float64), np.asarray(truth, np.float64)
    true_norm = np.linalg.norm(truth, axis=0)
    lit = true_norm > threshold * true_norm.max()
    if not np.any(lit):
        return float("nan")
    est, ref = cube[:, lit], truth[:, lit]
    cosine = np.sum(est * ref, axis=0) / (np.linalg.norm(est, axis=0) * true_norm[lit] + 1e-300)
    return float(np.degrees(np.mean(np.arccos(np.clip(cosine, -1, 1)))))


def relative_error(cube: np.ndarray, reference: np.ndarray) -> float:
    """‖cube − reference‖₂ / ‖reference‖₂."""
    reference = np.asarray(reference, np.float64)
    return float(np.linalg.norm(np.asarray(cube, np.float64) - reference) / np.linalg.norm(reference))


def bar_detail(cube: np.ndarray, truth: np.ndarray, masks: np.ndarray, size: int = 9) -> list[float]:
    """How much of a resolution chart's fine detail a cube keeps, per region: the band-summed image minus its
    ``size``-pixel local mean, correlated (Pearson) with the truth's over the bounding box of each mask's lit pixels
    (``masks``: (n, H, W), e.g. the demo's four quadrants)."""
    from scipy.ndimage import uniform_filter

    def detail(c):
        image = np.sum(np.asarray(c, np.float64), axis=0)
        return image - uniform_filter(image, size, mode="nearest")

    ours, theirs = detail(cube), detail(truth)
    out = []
    for mask in masks:
        rows, cols = np.nonzero(mask)
        box = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
        out.append(float(np.corrcoef(ours[box].ravel(), theirs[box].ravel())[0, 1]))
    return out
