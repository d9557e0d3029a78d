"""When a solve changes space: band space → spectral subspace → moves between bases → back, as pure decisions
(host arrays in, an action out: :class:`Stay`, :class:`Enter`, :class:`Move`, :class:`Leave`); the phases
(:mod:`clsdcam.solve.phases`) observe the solve and carry them out.

The default stays in band space: no signal read during a solve certifies that a basis holds the spectra the full
problem would find (on scenes of many smooth, overlapping spectra the automatic subspace cost 3.6–5.1° of
spectral angle at full size, with a basis of 21 vectors for 8 true spectra), and the accuracy rule
(docs/accuracy.md) admits no loss. ``Settings.subspace`` turns the automatic subspace on, as a speed option.

The basis is read from the spectra as the spectral angle weighs them: the unit spectra of the lit pixels of the
sensor window (:func:`clsdcam.solve.subspace.lit_shapes`), so a faint object's spectrum counts as much as a bright
one's;
``rank_for(ENTRY_TAIL)`` directions leave at most that mean sin² of them outside.

1. Band space for ``WARMUP`` iterations, then until the spectra settle (:func:`has_settled`, read every
   ``SETTLE_EVERY`` iterations): the previous basis holds the current lit spectra within ``SETTLED`` (mean sin²)
   of the current one, and at most K/2 vectors hold them. A subspace entered before then freezes spectra that
   band space is still finding (a faint line, a line at a weak filter's edge); spectra that never settle into
   K/2 directions are solved in band space. After a warm start the spectra are known: no warm-up; with
   ``--rank R`` WARMUP iterations only.
2. :func:`on_entry`: onto the basis (c = Bᵀx, ``--rank R``: R vectors), where A·B costs 4r FFTs per iteration.
   A basis of more than K/2 vectors would not pay: the solve stays in band space.
3. :func:`on_check`, every ``CHECK_EVERY`` iterations, from one full-space proximal-gradient step x⁺ from v = B·c:
   the basis is read again from x⁺'s lit spectra, at a rank that never falls (spectra the scene has shown stay:
   the "core" rank) but grows when they need more directions; when the step also lowers the data term by more
   than ``WIDEN_GAIN`` (relative), the measurement holds content the basis cannot represent, and up to as many
   directions again are added: those the step turns the lit spectra towards
   (:func:`clsdcam.solve.subspace.turning_directions`). When r would pass K/2 the solve returns to band space.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .subspace import Spectra, lit_shapes, turning_directions

WARMUP = 10
SETTLE_EVERY = 10
SETTLED = 5e-3             # the previous basis holds the spectra this close to the current one: settled
ENTRY_TAIL = 5e-3          # the basis leaves at most this mean sin² of the lit spectra outside
CHECK_EVERY = 25
WIDEN_GAIN = 1e-2
MAX_RANK_FRACTION = 0.5


@dataclass(frozen=True)
class Stay:
    """Stay in the current space (``why``: a line for the skip report, or None)."""

    why: str | None = None


@dataclass(frozen=True)
class Enter:
    """Onto ``basis`` (K × r) from band space; ``core``: the directions the scene's spectra have needed."""

    basis: np.ndarray
    core: int
    how: str
    captured: float = 1.0


@dataclass(frozen=True)
class Move:
    """From one basis to another (``widened``: more vectors than before)."""

    basis: np.ndarray
    core: int
    widened: bool = False


@dataclass(frozen=True)
class Leave:
    """Back to band space: a wider basis would not pay (``core``: the directions the spectra needed)."""

    core: int


@dataclass(frozen=True)
class Reading:
    """The spectra of a band-space window: their Gram eigensystem, the basis at the entry rank (or --rank), and
    the lit unit spectra."""

    spectra: Spectra
    basis: np.ndarray
    shapes: np.ndarray


def subspace_allowed(skip: bool, rank: int, subspace: bool, n_bands: int) -> bool:
    """Whether the settings let the solve leave band space (fewer than 4 bands: r ≤ K/2 saves too little)."""
    if not skip:
        return False
    if rank:
        return rank < n_bands
    return subspace and n_bands * MAX_RANK_FRACTION >= 2


def read(window: np.ndarray, rank: int) -> Reading:
    """The reading of a host (K, H, W) window (``rank``: a fixed basis size, 0 for ENTRY_TAIL's)."""
    shapes = lit_shapes(window)
    spectra = Spectra.of_shapes(shapes)
    return Reading(spectra, spectra.basis(rank or spectra.rank_for(ENTRY_TAIL)), shapes)


def held(shapes: np.ndarray, basis: np.ndarray) -> float:
    """Mean cos² of unit spectra (K, N) in span(basis): 1 − their mean sin² outside it."""
    return float(np.mean(np.sum((basis.T @ shapes) ** 2, axis=0))) if shapes.shape[1] else 1.0


def has_settled(previous: np.ndarray, current: Reading, n_bands: int) -> bool:
    """The previous basis holds the current lit spectra within SETTLED of the current one, in ≤ K/2 vectors."""
    settled = held(current.shapes, current.basis) - held(current.shapes, previous) <= SETTLED
    return settled and current.basis.shape[1] <= n_bands * MAX_RANK_FRACTION


def on_entry(reading: Reading, fixed_rank: int, n_bands: int) -> Enter | Stay:
    """Enter the reading's basis, unless it needs more than K/2 vectors (and the user did not fix the rank)."""
    rank = reading.basis.shape[1]
    if rank > n_bands * MAX_RANK_FRACTION and not fixed_rank:
        return Stay(f"{rank} directions hold the spectra: band space is cheaper")
    how = f"--rank {rank}" if fixed_rank else \
        f"spectra settled; a mean sin² of at most {ENTRY_TAIL:g} of the lit spectra outside"
    return Enter(reading.basis, rank, how, reading.spectra.captured(rank))


def on_check(before: np.ndarray, stepped: np.ndarray, gain: float, basis: np.ndarray, core: int, fixed_rank: int,
             n_bands: int) -> Move | Leave:
    """After a full step from ``before`` to ``stepped`` (host windows) that lowered the data term by ``gain``: the
    basis read again (``fixed_rank``: at that size, from ``stepped`` alone: ``before`` and ``gain`` may be None),
    never below the core rank, widened by the turning directions when the gain passes WIDEN_GAIN; Leave when it
    would pass K/2."""
    spectra = Spectra.of_shapes(lit_shapes(stepped))
    if fixed_rank:
        return Move(spectra.basis(basis.shape[1]), core)
    core = max(core, spectra.rank_for(ENTRY_TAIL))
    kept = spectra.basis(core)
    turns = turning_directions(kept, before, stepped, core if gain > WIDEN_GAIN else 0)
    wider, _ = np.linalg.qr(np.hstack([kept, turns]))
    if wider.shape[1] > n_bands * MAX_RANK_FRACTION:
        return Leave(core)
    return Move(wider, core, widened=wider.shape[1] > basis.shape[1])
