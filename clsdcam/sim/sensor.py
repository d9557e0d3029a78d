"""The sensor's pixel grid, shared by the PSF, the filter array and the scenes.

Pixel i covers [i, i+1) in pixel units; a grid ``s`` times finer samples each pixel at
(m + ½)/s, m = 0 … s·H − 1 (rows) and s·W − 1 (columns).
"""
from __future__ import annotations

import numpy as np

from ..camera.prototype import SENSOR_SHAPE as DEFAULT_SHAPE  # noqa: F401 - the simulator's default sensor


def ray_grid(shape, oversample: int):
    """Ray positions (y, x) in pixel units (pixel i covers [i, i+1)): (m + ½)/s on the fine grid."""
    y = (np.arange(oversample * shape[0]) + 0.5) / oversample
    x = (np.arange(oversample * shape[1]) + 0.5) / oversample
    return np.meshgrid(y, x, indexing="ij")
