"""Where the scene field, the sensor window and the PSF sit relative to each other.

Conventions (docs/conventions.md): the PSF's origin is its centre pixel c = (H//2, W//2); the scene
field (Hp, Wp) holds the sensor window (H, W) at ``offset`` = (oy, ox); the cube written to
files is that window. With h_c(s) = psf[c + s] for offsets s in the PSF's support
[s_lo, s_hi] (per axis),

    b(y) = Σ_Q h_c(oy + y − Q) v(Q)      (y on the sensor, Q in the field),

which a circular convolution of period Hp reproduces exactly when the field holds every
scene point that can reach the sensor and no wrapped one can:

    oy ≥ max(s_hi, 0)   and   Hp − oy − H ≥ max(−s_lo, 0).

Two fields:

* the paper's (the full solver, ``--no-skip``): 2H × 2W, window centred, the whole PSF frame;
* the support field (``--support-field``, a speed option): the PSF's measured support (the box holding all but
  ``SUPPORT_TAIL`` of its L1 mass; the few tail values outside it are dropped), each side
  grown to a length the FFT engine transforms fast; scene area the PSF cannot bring onto the
  sensor is not part of the problem.

The transfer function is built with the window at the FFT origin (the kernel shifted by the
offset), so A's crop and Aᵀ's pad are the first H rows and W columns of the transform:
pruned transforms need no offset arithmetic.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..errors import InputError

SUPPORT_TAIL = 1e-4     # L1 mass of the PSF left outside its measured support


@dataclass(frozen=True)
class FieldGeometry:
    """The field, the window in it, and the PSF offsets kept (inclusive, relative to its centre)."""

    sensor: tuple[int, int]
    field: tuple[int, int]
    offset: tuple[int, int]
    support: tuple[tuple[int, int], tuple[int, int]]   # ((s_lo, s_hi) rows, (s_lo, s_hi) columns)

    @property
    def voxels_per_band(self) -> int:
        return self.field[0] * self.field[1]


def psf_centre(shape) -> tuple[int, int]:
    return (shape[0] // 2, shape[1] // 2)


def window_offset(sensor_shape, field_shape) -> tuple[int, int]:
    """The centred window: (Hp//2 − H//2, Wp//2 − W//2)."""
    return tuple(f // 2 - s // 2 for s, f in zip(sensor_shape, field_shape))


def default_field_shape(sensor_shape) -> tuple[int, int]:
    """The paper's field: twice the sensor in each direction."""
    return tuple(2 * s for s in sensor_shape)


def whole_frame_support(sensor_shape) -> tuple[tuple[int, int], tuple[int, int]]:
    """Every PSF pixel: offsets −c … n − 1 − c on each axis."""
    return tuple((-c, n - 1 - c) for n, c in zip(sensor_shape, psf_centre(sensor_shape)))


def centred_geometry(sensor_shape, field_shape=None) -> FieldGeometry:
    """The paper's geometry (2H × 2W unless ``field_shape`` is given): centred window, whole PSF frame."""
    sensor = tuple(int(s) for s in sensor_shape)
    field = tuple(int(f) for f in (field_shape or default_field_shape(sensor)))
    if any(f < s for s, f in zip(sensor, field)):
        raise InputError(f"field {field} is smaller than the sensor {sensor}")
    return FieldGeometry(sensor, field, window_offset(sensor, field), whole_frame_support(sensor))


def psf_support(psf: np.ndarray, tail: float = SUPPORT_TAIL) -> tuple[tuple[int, int], tuple[int, int]]:
    """The box holding all but ``tail`` of Σ|h| (tail/4 trimmed from each side), as offsets from the centre."""
    mass = np.abs(np.asarray(psf, dtype=np.float64))
    total = mass.sum()
    if not total > 0:
        raise InputError("psf: all zero, nothing can reach the sensor")
    return tuple(_trimmed_range(mass.sum(axis=1 - axis), tail / 4 * total, centre)
                 for axis, centre in enumerate(psf_centre(psf.shape)))


def _trimmed_range(profile: np.ndarray, trim: float, centre: int) -> tuple[int, int]:
    """First and last index of ``profile`` once ``trim`` of its mass is cut from each end, minus ``centre``."""
    below = np.cumsum(profile)
    above = below[-1] - np.concatenate(([0.0], below[:-1]))      # mass from index i to the end
    lo = int(np.argmax(below > trim))
    hi = int(len(profile) - 1 - np.argmax(above[::-1] > trim))
    return lo - centre, hi - centre


def support_geometry(psf: np.ndarray, fast_length: Callable[[int], int], tail: float = SUPPORT_TAIL) -> FieldGeometry:
    """The smallest field the PSF's support needs, each side grown to ``fast_length``; slack split evenly."""
    sensor = tuple(psf.shape)
    support = psf_support(psf, tail)
    field, offset = [], []
    for n, (lo, hi) in zip(sensor, support):
        before, after = max(hi, 0), max(-lo, 0)       # scene rows above / below the window that reach it
        needed = n + before + after
        length = int(fast_length(needed))
        field.append(length)
        offset.append(before + (length - needed) // 2)
    return FieldGeometry(sensor, tuple(field), tuple(offset), support)


def transfer_function(psf: np.ndarray, geometry: FieldGeometry) -> np.ndarray:
    """Ĥ = rfft2(k) (float64 host), k[(s − o) mod field] = h_c(s) for s in the support: the window at the FFT origin."""
    kernel = np.zeros(geometry.field)
    centre = psf_centre(psf.shape)
    rows, cols = (np.arange(lo, hi + 1) for lo, hi in geometry.support)
    kernel[np.ix_((rows - geometry.offset[0]) % geometry.field[0], (cols - geometry.offset[1]) % geometry.field[1])] = \
        np.asarray(psf, dtype=np.float64)[np.ix_(rows + centre[0], cols + centre[1])]
    return np.fft.rfft2(kernel)
