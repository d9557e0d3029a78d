"""Bands: the sweep's fine transmission t(λ) integrated into K bands [a_k, b_k].

    F_k(y, x) = ∫_{a_k}^{b_k} t(λ; y, x) dλ

with t the piecewise-linear curve through the sweep's samples (λ_i, t_i): the trapezoid rule on the samples
strictly inside the band plus the band's two ends, where t is interpolated linearly (exact for that curve, and
additive: two adjacent bands sum to their union). ``--bands K --range A:B`` gives K equal bands, edges
A + k(B − A)/K; ``--band-edges CSV`` gives the K + 1 increasing edges (first column). The band wavelengths are
the centres (a_k + b_k)/2, as :func:`clsdcam.sim.band_wavelengths` places them.
"""
from __future__ import annotations

import numpy as np

from ..errors import InputError
from .tables import read_table


def equal_edges(n_bands: int, lo: float, hi: float) -> np.ndarray:
    """K + 1 edges of K equal bands over [lo, hi]."""
    if not (n_bands >= 1 and hi > lo):
        raise InputError(f"--bands {n_bands} --range {lo:g}:{hi:g}: need K ≥ 1 and A < B")
    return np.linspace(lo, hi, n_bands + 1)


def edges_from_csv(path) -> np.ndarray:
    """The K + 1 band edges of a CSV (first column), increasing."""
    edges = read_table(path, "--band-edges", 1)[:, 0]
    if edges.size < 2 or np.any(np.diff(edges) <= 0):
        raise InputError(f"--band-edges {path}: need at least 2 increasing edges (K + 1 for K bands)")
    return edges


def band_centres(edges: np.ndarray) -> np.ndarray:
    return 0.5 * (edges[:-1] + edges[1:])


def check_edges(edges: np.ndarray, wavelengths: np.ndarray) -> None:
    """InputError unless every band lies inside the sweep [λ_0, λ_{N−1}] (t is not extrapolated)."""
    if wavelengths.size < 2 or edges[0] < wavelengths[0] or edges[-1] > wavelengths[-1]:
        raise InputError(f"bands {edges[0]:g}–{edges[-1]:g} nm do not lie inside the sweep "
                         f"{wavelengths[0]:g}–{wavelengths[-1]:g} nm ({wavelengths.size} wavelengths)")


def integrate_bands(wavelengths: np.ndarray, values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(K, …) band integrals of ``values`` (N, …) sampled at increasing ``wavelengths`` (N,) (module docstring)."""
    check_edges(edges, wavelengths)
    out = np.empty((edges.size - 1,) + values.shape[1:])
    for k, (a, b) in enumerate(zip(edges[:-1], edges[1:])):
        inside = np.flatnonzero((wavelengths > a) & (wavelengths < b))
        x = np.concatenate([[a], wavelengths[inside], [b]])
        y = np.concatenate([_at(wavelengths, values, a)[None], values[inside], _at(wavelengths, values, b)[None]])
        out[k] = np.tensordot(np.diff(x), 0.5 * (y[1:] + y[:-1]), axes=1)   # Σ Δλ (t_j + t_{j+1}) / 2
    return out


def _at(wavelengths: np.ndarray, values: np.ndarray, lam: float) -> np.ndarray:
    """values linearly interpolated along axis 0 at ``lam`` (inside the samples)."""
    i = int(np.clip(np.searchsorted(wavelengths, lam, side="right") - 1, 0, wavelengths.size - 2))
    w = (lam - wavelengths[i]) / (wavelengths[i + 1] - wavelengths[i])
    return (1 - w) * values[i].astype(np.float64) + w * values[i + 1]
