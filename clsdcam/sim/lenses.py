"""Lens comparators for the diffuser (the paper's Fig. 7): a focused lens's PSF is a small square spot.

A lens focusing onto a spot of ``spot_px`` × ``spot_px`` pixels has h = 1/spot_px on the spot
and 0 elsewhere (‖h‖₂ = 1): a high-NA lens resolves one filter pixel (2 px), a low-NA lens one
super-pixel (an 8×8 tile of 2-pixel filters, 16 px). :data:`DESIGNS` names the three PSFs
compared: the diffuser's caustic and the two lenses.
"""
from __future__ import annotations

import numpy as np

from .caustic import caustic_psf
from .filters import TILE
from .sensor import DEFAULT_SHAPE

SUPERPIXEL_PX = TILE * 2  # one 8×8 tile of 2-pixel filters


def lens_psf(shape=DEFAULT_SHAPE, spot_px: int = 2) -> np.ndarray:
    """A focused lens: a uniform ``spot_px`` × ``spot_px`` square at the frame centre (H//2, W//2)
    (top-left corner (H//2 − (spot_px−1)//2, …)), unit L2 norm, float32.

    spot_px = 2 (one filter pixel) is the paper's high-NA lens; 16 (one super-pixel) its low-NA lens.
    """
    psf = np.zeros(shape, np.float32)
    y0, x0 = shape[0] // 2 - (spot_px - 1) // 2, shape[1] // 2 - (spot_px - 1) // 2
    psf[y0:y0 + spot_px, x0:x0 + spot_px] = 1.0
    return psf / np.linalg.norm(psf)


DESIGNS = {  # name -> PSF builder (shape, seed)
    "diffuser": lambda shape, seed: caustic_psf(shape, seed),
    "low-NA lens": lambda shape, seed: lens_psf(shape, SUPERPIXEL_PX),
    "high-NA lens": lambda shape, seed: lens_psf(shape, 2),
}
