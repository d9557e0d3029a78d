"""The space policy (clsdcam.solve.space_policy): pure decisions from host arrays to Stay / Enter / Move / Leave."""
import numpy as np
import pytest

from clsdcam.solve.space_policy import (ENTRY_TAIL, WIDEN_GAIN, Enter, Leave, Move, Stay, has_settled, on_check,
                                        on_entry, read, subspace_allowed)

K = 8


def window(*spectra, pixels=6) -> np.ndarray:
    """A (K, len(spectra), pixels) window: row i of pixels all holding spectrum i."""
    return np.stack([np.repeat(np.asarray(s, float)[:, None], pixels, axis=1) for s in spectra], axis=1)


def unit(*weights) -> np.ndarray:
    v = np.zeros(K)
    v[:len(weights)] = weights
    return v


@pytest.mark.parametrize("skip, rank, subspace, bands, allowed", [
    (True, 0, False, 64, False),      # the default: band space
    (True, 0, True, 64, True),
    (True, 0, True, 3, False),        # too few bands to save anything
    (True, 8, False, 64, True),
    (True, 64, False, 64, False),     # a basis as large as the bands is band space
    (False, 8, True, 64, False),      # --no-skip
])
def test_what_the_settings_allow(skip, rank, subspace, bands, allowed):
    assert subspace_allowed(skip, rank, subspace, bands) == allowed


def test_a_reading_finds_the_directions_of_the_lit_spectra():
    reading = read(window(unit(1), unit(0, 1), unit(0, 0, 1), unit(0, 0, 0, 1e-4)), rank=0)
    assert reading.basis.shape == (K, 3)                       # the unlit fourth pixel row is not counted
    assert np.allclose(np.abs(reading.basis.T @ reading.basis), np.eye(3))
    assert read(window(unit(1), unit(0, 1), unit(0, 0, 1)), rank=2).basis.shape == (K, 2)


def test_spectra_settle_when_the_previous_basis_still_holds_them():
    reading = read(window(unit(1), unit(0, 1)), rank=0)
    assert has_settled(reading.basis, reading, K)
    assert not has_settled(np.eye(K)[:, 4:6], reading, K)       # a basis orthogonal to them: not settled
    wide = read(window(*np.eye(K)[:5]), rank=0)                  # 5 directions > K/2
    assert not has_settled(wide.basis, wide, K)


def test_entry_declines_a_basis_wider_than_half_the_bands_unless_the_rank_is_fixed():
    wide = read(window(*np.eye(K)[:5]), rank=0)
    stay = on_entry(wide, fixed_rank=0, n_bands=K)
    assert isinstance(stay, Stay) and "5 directions" in stay.why
    narrow = on_entry(read(window(unit(1), unit(0, 1)), rank=0), fixed_rank=0, n_bands=K)
    assert isinstance(narrow, Enter) and narrow.core == 2 and f"{ENTRY_TAIL:g}" in narrow.how
    fixed = on_entry(read(window(*np.eye(K)[:5]), rank=6), fixed_rank=6, n_bands=K)
    assert isinstance(fixed, Enter) and fixed.basis.shape == (K, 6) and fixed.how == "--rank 6"


def test_a_check_widens_towards_where_a_full_step_turns_the_spectra():
    before = window(unit(1), unit(1))
    stepped = window(unit(1), unit(1, 0.5))
    action = on_check(before, stepped, gain=2 * WIDEN_GAIN, basis=np.eye(K)[:, :1], core=1, fixed_rank=0, n_bands=K)
    assert isinstance(action, Move) and action.widened and action.core == 2
    assert np.linalg.norm(action.basis.T @ unit(0, 1)) > 0.999     # the new direction is in the basis


def test_a_check_keeps_a_fixed_rank_and_leaves_when_the_spectra_need_more_than_half_the_bands():
    stepped = window(*np.eye(K)[:3])
    fixed = on_check(stepped, stepped, gain=0.5, basis=np.eye(K)[:, :2], core=2, fixed_rank=2, n_bands=K)
    assert isinstance(fixed, Move) and fixed.basis.shape == (K, 2) and not fixed.widened and fixed.core == 2
    leave = on_check(stepped, stepped, gain=0.0, basis=np.eye(K)[:, :2], core=2, fixed_rank=0, n_bands=4)
    assert leave == Leave(core=3)


def test_decisions_are_pure():
    before, stepped = window(unit(1), unit(1)), window(unit(1), unit(1, 0.5))
    copies = before.copy(), stepped.copy()
    first = on_check(before, stepped, 0.5, np.eye(K)[:, :1], 1, 0, K)
    again = on_check(before, stepped, 0.5, np.eye(K)[:, :1], 1, 0, K)
    assert np.array_equal(first.basis, again.basis) and first.core == again.core
    assert np.array_equal(before, copies[0]) and np.array_equal(stepped, copies[1])
