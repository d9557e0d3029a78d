"""Accuracy of a reconstructed cube against the truth."""
from __future__ import annotations

import numpy as np

BRIGHT = 0.5    # the truth's brightest points: where its peak over bands reaches this fraction of its largest


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


def peak_ratio(cube: np.ndarray, truth: np.ndarray, bright: float = BRIGHT) -> float:
    """How much of the truth's peaks the cube reaches: the mean of ĉ(p) / t̂(p) over the truth's brightest points
    P = {p : t̂(p) ≥ ``bright`` · max t̂}, where t̂(p) = max_k truth(k, p) and ĉ(p) = max_k cube(k, p) are the
    peaks over bands at pixel p. 1 when the peaks are recovered where they are; NaN for a truth without light.

    On a sparse scene (point sources on a dark ground) PSNR, normalised by the truth's peak over a cube that is
    mostly dark, can read high while the sources are spread out or lost: this says what is left of them.
    """
    cube_peak = np.max(np.asarray(cube, np.float64), axis=0)
    truth_peak = np.max(np.asarray(truth, np.float64), axis=0)
    if not truth_peak.max() > 0:
        return float("nan")
    points = truth_peak >= bright * truth_peak.max()
    return float(np.mean(cube_peak[points] / truth_peak[points]))


def accuracy(cube: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """The figures clsdcam reports against a truth: ``psnr`` (dB), ``spectral_angle`` (mean, °), ``peak_ratio``.
    A cube of NaN (a failed frame) has NaN figures."""
    return {"psnr": psnr(cube, truth), "spectral_angle": spectral_angle(cube, truth),
            "peak_ratio": peak_ratio(cube, truth)}


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
