"""What a scene doesn't need, decided once per calibration or per solve, and what skipping it saved.

* field (``--support-field``; off by default, docs/accuracy.md): the scene area the PSF cannot bring onto the
  sensor is not part of the problem (support-sized field, :func:`clsdcam.camera.geometry.support_geometry`). The
  solve is not the paper's field's: the paper's field keeps a margin of unknowns the data never touch, which
  the TV prox moves only slowly from zero, and it shapes how the scene just outside the window is estimated
  (0.2 dB at 500 iterations on a real cube at full size, docs/accuracy.md);
* bands: a band no pixel's filter sees adds nothing to b and gets no gradient: no FFTs for it;
* subspace (``--subspace`` or ``--rank``; off by default, docs/accuracy.md): when the scene's spectra span few
  dimensions, r spectral basis vectors instead of K bands (:mod:`clsdcam.solve.subspace`): 4r FFTs per iteration
  instead of 4K;
* terms: a regulariser with zero weight is never evaluated.

Work is counted in 2-D FFT voxels (transforms × field size), against the full solver's: the
paper's 2H × 2W field, every band, every iteration. ``--no-skip`` is that full solver.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..backends import seen_bands
from ..errors import shape_text
from ..camera.geometry import FieldGeometry, centred_geometry, support_geometry


def plan_geometry(psf: np.ndarray, backend, support: bool) -> FieldGeometry:
    """The support-sized field at the engine's fast lengths (``support``), or the paper's 2H × 2W."""
    return support_geometry(psf, backend.fast_length) if support else centred_geometry(psf.shape)


@dataclass
class SkipReport:
    """The skips taken in one solve, as lines a person reads and numbers a benchmark reads."""

    lines: list[str] = field(default_factory=list)
    full_work: float = 0.0      # FFT voxels the full solver would have transformed
    done_work: float = 0.0      # FFT voxels transformed (the subspaces' checks and power iterations included)

    @property
    def saved(self) -> float:
        """Fraction of the full solver's FFT work not done."""
        return 1.0 - self.done_work / self.full_work if self.full_work else 0.0

    def summary(self) -> str:
        """One skip per line, then the FFT work saved."""
        return "\n".join(self.lines + [f"FFT work saved: {100 * self.saved:.0f}% (of the full solver's 2-D FFT voxels)"])


def field_line(geometry: FieldGeometry) -> str:
    paper = centred_geometry(geometry.sensor)
    if geometry.field == paper.field:
        return f"field: none cut: {shape_text(geometry.field)} (the paper's)"
    (ylo, yhi), (xlo, xhi) = geometry.support
    cut = 1.0 - geometry.voxels_per_band / paper.voxels_per_band
    return (f"field: {shape_text(geometry.field)} instead of {shape_text(paper.field)} ({100 * cut:.0f}% of the paper's "
            f"field cut; PSF support rows {ylo}…{yhi}, columns {xlo}…{xhi} from its centre)")


def bands_line(filters: np.ndarray) -> str | None:
    unseen = np.flatnonzero(~seen_bands(filters))
    if not len(unseen):
        return None
    return f"bands: {len(unseen)} of {len(filters)} unseen by every filter ({', '.join(map(str, unseen[:8]))}" + \
        ("…" if len(unseen) > 8 else "") + "): no FFTs for them"


def terms_line(off: list[str]) -> str | None:
    return f"terms: {', '.join(off)} (zero weight) not computed" if off else None


def subspace_line(rank: int, n_bands: int, start: int, captured: float, reason: str) -> str:
    if rank >= n_bands:
        return f"subspace: none ({reason})"
    vectors = "vector" if rank == 1 else "vectors"
    return (f"subspace: {rank} spectral basis {vectors} instead of {n_bands} bands from iteration {start} "
            f"(holding {100 * captured:.1f}% of the lit spectra; {reason})")
