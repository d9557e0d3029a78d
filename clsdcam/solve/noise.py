"""The measurement's noise level, from the residual b − Av of an iterate.

A raw lensless frame is no place to measure noise: the filter array and the caustic give it texture at
the pixel scale (a median-absolute-deviation estimate on the raw frame comes out 2–10× the true noise
on the simulator's scenes). The model reproduces that texture, so the residual r = b − Av of an iterate
that already fits the scene's coarse structure is noise plus what is not yet fitted. What is not yet
fitted still has edges at the pixel scale (the caustic's lines, the filter tiles); Donoho and Johnstone's
estimator reads the noise from the finest diagonal wavelet details (HH, Daubechies-2) of r, which pass white
noise whole but an edge only where it is diagonal, robustly:

    σ̂ = median|HH(r)| / 0.6745         (0.6745: the 75th percentile of |𝒩(0, 1)|)

(``skimage.restoration.estimate_sigma``'s estimator, read here straight from PyWavelets' ``dwtn``: importing
``skimage.restoration`` takes 0.4–0.7 s on this 2-core machine, paid inside the first solve of a process). On the
simulator's six panel scenes, 30 iterations in, σ̂ is within 0.97–1.42× the true noise at 320×448 (horizontal
pixel differences, the first design: 1.03–1.91×), and 0.95–1.16× at 128×160 (0.96–1.95×);
``tools/bench_accuracy.py`` reports it per scene (docs/benchmarks.md).
"""
from __future__ import annotations

import numpy as np

MAD_TO_SIGMA = 0.6744897501960817     # the 75th percentile of |𝒩(0, 1)|: σ = median|𝒩(0, σ²)| / it


def residual_noise(residual: np.ndarray) -> float:
    """σ̂ of a residual image (H, W) (see the module docstring)."""
    import pywt

    diagonal = pywt.dwtn(np.asarray(residual, np.float64), "db2")["dd"]
    return float(np.median(np.abs(diagonal)) / MAD_TO_SIGMA)
