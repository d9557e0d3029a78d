"""The measurement's noise level, from the residual b − Av of an iterate.

A raw lensless frame is no place to measure noise: the filter array and the caustic give it texture at
the pixel scale (a median-absolute-deviation estimate on the raw frame comes out 2–10× the true noise
on the simulator's scenes). The model reproduces that texture, so the residual r = b − Av of an iterate
that already fits the scene's coarse structure is noise plus what is not yet fitted, mostly smooth.
The noise is estimated from r's horizontal neighbour differences d = r(y, x+1) − r(y, x), robustly:

    σ̂ = 1.4826 · median|d − median d| / √2

(1.4826·MAD is σ for a Gaussian; a difference of two independent pixels has variance 2σ²). On the
simulator's scenes, 30 iterations in, σ̂ is within 0.7–1.7× the true noise (docs/benchmarks.md,
"Choosing ``--tv``").
"""
from __future__ import annotations

import numpy as np

MAD_TO_SIGMA = 1.4826


def residual_noise(residual: np.ndarray) -> float:
    """σ̂ of a residual image (H, W) (see the module docstring)."""
    d = np.diff(np.asarray(residual, np.float64), axis=1).ravel()
    return float(MAD_TO_SIGMA * np.median(np.abs(d - np.median(d))) / np.sqrt(2))
