"""Pixels to draw spectra at: one per distinct lit region of a cube, so that a picture of a few spectra shows
every kind of light in the scene (not four pixels of its brightest one).

For a cube v (K, H, W):

1. lit pixels: max_k v(k, y, x) ≥ LIT · (the PERCENTILE-th percentile of that peak over the image, its maximum
   when that is 0). The peak, not the band sum: a narrow line is as bright as white light in its band but sums
   to a few bands' worth.
2. groups of similar spectra, by leader clustering on unit spectra u = v/‖v‖₂, brightest first: the brightest
   lit pixel not yet grouped leads a new group, which takes every ungrouped lit pixel whose spectral angle to
   the leader is at most CLUSTER_ANGLE (u·u_leader ≥ cos CLUSTER_ANGLE); at most MAX_GROUPS groups are formed
   (a scene of smoothly varying spectra leaves the rest ungrouped).
3. the ``n`` largest groups holding at least MIN_SHARE of the lit pixels, each represented by its most central
   pixel: the maximum of the Euclidean distance from the group's pixels to the nearest pixel outside the group
   (the middle of its widest part, away from edges where a reconstruction blurs two regions together), the
   brightest among equals, and of those the nearest to their mean position;
4. numbered as the lights are named (the demo's target: red, green, blue, white): the narrow lights first, then the
   broad ones (at least BROAD of their bands reach half their peak: white light), each by the wavelength of the
   spectrum's peak, the longest first.
"""
from __future__ import annotations

import math

import numpy as np

LIT = 0.1               # a pixel is lit when its peak band reaches this fraction of the image's (percentile) peak
PERCENTILE = 99.5       # the image's peak: this percentile of the per-pixel peaks (robust to a few hot pixels)
CLUSTER_ANGLE = 25.0    # degrees: spectra within this angle of a group's leader join the group
MAX_GROUPS = 32         # groups formed at most
MIN_SHARE = 0.01        # a group must hold this fraction of the lit pixels to be drawn
MAX_POINTS = 6          # points drawn by default (one colour each)
BROAD = 0.5             # a light is broad (white) when this fraction of its bands reach half its peak


def spectrum_points(cube, wavelengths=None, n: int = MAX_POINTS) -> list[tuple[int, int]]:
    """Up to ``n`` (y, x) pixels of a (K, H, W) cube, one per distinct lit region (see the module docstring),
    numbered as the lights are named (:func:`light_order`; by band without ``wavelengths``); [] when nothing is
    lit."""
    cube = np.asarray(cube, dtype=np.float64)
    peak = cube.max(axis=0)
    reference = np.percentile(peak, PERCENTILE) or peak.max()    # the maximum when fewer pixels than that are lit
    if reference <= 0:
        return []
    lit = np.flatnonzero(peak.ravel() >= LIT * reference)
    labels = spectral_groups(cube.reshape(cube.shape[0], -1)[:, lit], peak.ravel()[lit])
    sizes = np.bincount(labels[labels >= 0], minlength=1)
    kept = [g for g in np.argsort(-sizes, kind="stable")[:n] if sizes[g] >= max(1, MIN_SHARE * lit.size)]
    points = [central_pixel(lit[labels == g], peak) for g in kept]
    order = np.arange(cube.shape[0]) if wavelengths is None else np.asarray(wavelengths, np.float64)
    return sorted(points, key=lambda p: light_order(cube[:, p[0], p[1]], order))


def light_order(spectrum: np.ndarray, wavelengths: np.ndarray) -> tuple[bool, float]:
    """The sort key that numbers lights as they are named (red, green, blue, white): narrow before broad (at least
    BROAD of the bands at half the peak or more), then the longest peak wavelength first."""
    broad = np.mean(spectrum >= 0.5 * spectrum.max()) >= BROAD
    return bool(broad), -float(wavelengths[np.argmax(spectrum)])


def spectral_groups(spectra: np.ndarray, brightness: np.ndarray) -> np.ndarray:
    """Group label per column of ``spectra`` (K, N) by leader clustering, brightest leader first; −1 for the
    columns left when MAX_GROUPS groups are formed."""
    norms = np.linalg.norm(spectra, axis=0)
    units = spectra / np.where(norms > 0, norms, 1.0)
    labels = np.full(spectra.shape[1], -1)
    threshold = math.cos(math.radians(CLUSTER_ANGLE))
    for group in range(MAX_GROUPS):
        free = np.flatnonzero(labels < 0)
        if free.size == 0:
            break
        leader = free[np.argmax(brightness[free])]
        labels[free[units[:, leader] @ units[:, free] >= threshold]] = group
    return labels


def central_pixel(members: np.ndarray, peak: np.ndarray) -> tuple[int, int]:
    """(y, x) of the flat indices ``members`` farthest from the group's edge (distance transform), the brightest
    (largest ``peak``) among equals, and of those the nearest to their mean position (the middle of a bar)."""
    from scipy.ndimage import distance_transform_edt

    mask = np.zeros(peak.size, bool)
    mask[members] = True
    depth = distance_transform_edt(mask.reshape(peak.shape)).ravel()[members]
    deepest = members[depth == depth.max()]
    brightest = deepest[peak.ravel()[deepest] == peak.ravel()[deepest].max()]
    yx = np.stack(np.unravel_index(brightest, peak.shape), axis=1)
    y, x = yx[np.argmin(((yx - yx.mean(axis=0)) ** 2).sum(axis=1))]
    return int(y), int(x)
