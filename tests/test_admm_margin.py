"""ADMM's margin correction (clsdcam.algorithms.admm.margin): the band of the lowest frequencies and the window's mask
on it, its masked system against the operator written in real space, the conjugate-gradient solve, the tracked
spectrum of ξ, and the fixed point it leaves where it is."""
import dataclasses

import numpy as np
import pytest
import scipy.fft

from clsdcam.algorithms.admm import balance
from clsdcam.algorithms.admm.host_steps import Splitting, difference, difference_adjoint_add
from clsdcam.algorithms.admm.margin import Band, MarginCorrection
from clsdcam.backends import rfft2_of_window
from clsdcam.backends.numpy import NumpyBackend
from test_admm import camera_steps

RNG = np.random.default_rng(11)


def nyquist_free(shape, leading=(), rng=RNG) -> np.ndarray:
    """A random real (…, h, w) field without its Nyquist row and column (h, w even)."""
    h, w = shape
    spectrum = scipy.fft.rfft2(rng.standard_normal(leading + shape))
    spectrum[..., h // 2, :] = spectrum[..., :, w // 2] = 0
    return scipy.fft.irfft2(spectrum, s=shape)


def test_the_bands_mask_is_the_windows_product_on_band_limited_fields():
    """For a real field of the band's frequencies alone, T·ẑ is the band of (M·z)^ (M the window, a rectangle at the
    origin), and taking the band then adding it to zeros gives the field's spectrum back."""
    band = Band((12, 18), (5, 7), (3, 4))
    spectrum = np.zeros((2, 12, 10), complex)
    band.add(spectrum, band.take(scipy.fft.rfft2(RNG.standard_normal((2, 12, 18)))))
    field = scipy.fft.irfft2(spectrum, s=(12, 18))
    assert np.allclose(scipy.fft.rfft2(field), spectrum, atol=1e-12)         # real: the band is Hermitian-whole
    windowed = np.zeros_like(field)
    windowed[:, :5, :7] = field[:, :5, :7]
    np.testing.assert_allclose(band.masked(band.take(spectrum)), band.take(scipy.fft.rfft2(windowed)), atol=1e-12)


def masked_operator(split, v: np.ndarray) -> np.ndarray:
    """(μ₁HᵀMH + Σ_d μ₂,dD_dᵀD_d + μ₃I)·v in real space, from the host steps' own convolution and differences (M the
    sensor window), in float64."""
    (h, w), p = split.sensor_shape, split.penalties
    hv = split.convolve(v)
    hv[:, h:], hv[:, :h, w:] = 0, 0
    out = p.data * scipy.fft.irfft2(scipy.fft.rfft2(hv) * np.conj(split.transfer), s=split.field_shape) + p.nonneg * v
    for axis in split.axes:
        difference_adjoint_add(difference(v, axis, np.empty_like(v)), axis, p.tv_along(axis), out)
    return out


def test_on_the_whole_spectrum_the_system_is_the_masked_c_steps():
    """With every frequency but the Nyquist ones in the band, ΠAΠ (applied in the modes along λ) is
    :func:`masked_operator` on fields without Nyquist content (its band), P⁻¹ inverts its unmasked part, the band's
    inner product is the fields' (and the modes'), and 200 conjugate-gradient steps solve A·δ = r."""
    _, split = camera_steps(Splitting, RNG, shape=(4, 6))
    system = MarginCorrection(split, 200, tuple(n // 2 for n in split.field_shape))
    band = system.band
    v = nyquist_free(split.field_shape, (split.n_bands,))
    spectrum = band.take(scipy.fft.rfft2(v))
    direct = band.take(scipy.fft.rfft2(masked_operator(split, v)))
    modes = system._modes(spectrum)
    assert np.abs(system._bands(system._apply(modes)) - direct).max() < 1e-12 * np.abs(direct).max()
    unmasked = system._apply(modes) + system._pulled(system.transfer * modes)
    assert np.abs(system._precondition(unmasked) - modes).max() < 1e-12 * np.abs(spectrum).max()
    u = nyquist_free(split.field_shape, (split.n_bands,))
    other = band.take(scipy.fft.rfft2(u))
    assert system._dots(spectrum, other).sum() == pytest.approx(np.prod(split.field_shape) * np.sum(v * u))
    assert system._dots(modes, system._modes(other)).sum() == pytest.approx(system._dots(spectrum, other).sum())
    r = system._apply(system._modes(other))
    assert np.abs(system._apply(system._solve(r)) - r).max() < 1e-9 * np.abs(r).max()


def test_each_mode_has_its_own_gradients():
    """Three steps on a residual in two modes are the sum of three steps on each mode's part alone (one set of step
    lengths for the whole band would mix them), and a mode with no residual stays at zero."""
    _, split = camera_steps(Splitting, RNG, shape=(8, 10))
    system = MarginCorrection(split, 3)
    r = system._apply(system._modes(system.band.take(scipy.fft.rfft2(RNG.standard_normal(split.shape)))))
    first, second = np.zeros_like(r), np.zeros_like(r)
    first[0], second[1] = r[0], 100 * r[1]
    both = system._solve(first + second)
    assert np.abs(both - system._solve(first) - system._solve(second)).max() < 1e-12 * np.abs(both).max()
    assert not both[2:].any() and np.abs(both[:2]).min(axis=(1, 2)).all()


def relaxed_steps(shape=(8, 10), steps=3):
    """A camera's steps with over-relaxation 1.7 and the margin's correction of ``steps`` steps."""
    _, split = camera_steps(Splitting, np.random.default_rng(5), shape=shape)
    split.relaxation, split.margin_steps = 1.7, steps
    split.set_penalties(split.penalties)
    return split


def direct_margin_band(split, state) -> np.ndarray:
    return split.margin.band.take(rfft2_of_window(state.xi, split.field_shape))


def test_a_correction_is_the_band_of_a_real_fields_spectrum():
    """Band.real keeps a real field's band and drops the part of the k_x = 0 column that no real field has (its
    anti-Hermitian part along k_y), as an inverse real transform drops it."""
    band = Band((12, 18), (5, 7), (3, 4))
    real = band.take(scipy.fft.rfft2(RNG.standard_normal((2, 12, 18))))
    odd, column = np.zeros_like(real), RNG.standard_normal(real.shape[:-1])
    odd[..., 0] = column - column[..., ::-1]                      # anti-Hermitian along k_y: z_−k = −conj z_k
    assert np.abs(odd[..., 0]).max() > 0.1
    np.testing.assert_allclose(band.real(real + odd), real, atol=1e-12)


def test_the_tracked_spectrum_of_the_margin_band_is_its_transform():
    """After each c-step, Ξ (tracked by the recursion from the window's change) is the low band of ξ's spectrum, over
    40 relaxed iterations; a new data penalty, which rescales ξ, has it transformed again."""
    split = relaxed_steps()
    state, _ = split.start(np.zeros(split.shape))
    for _ in range(40):
        split.c_step(state)
        tracked = state.margin_band
        assert np.abs(tracked - direct_margin_band(split, state)).max() < 1e-10 * np.abs(tracked).max()
        split.splits(state, split.relaxation)
    new = dataclasses.replace(split.penalties, data=0.5 * split.penalties.data)
    balance.repenalise(split, state, NumpyBackend("float64"), new)
    assert state.margin_band is None
    split.c_step(state)
    assert np.abs(state.margin_band - direct_margin_band(split, state)).max() < 1e-10 * np.abs(direct_margin_band(
        split, state)).max()


def converged(split, state, limit=40000):
    for _ in range(limit):
        _, (step, norm) = split.iterate(state)
        if 0 < norm and step <= 1e-28 * norm:
            return state.w.copy()
    raise AssertionError("no fixed point")


def test_the_correction_leaves_the_fixed_point_where_it_is():
    """ADMM's fixed point, reached without the correction, stays where it is with it (three steps on the band);
    and ADMM with it from the start reaches the same point."""
    split = relaxed_steps(steps=0)
    state, _ = split.start(np.zeros(split.shape))
    at = converged(split, state)
    split.margin_steps = 3
    split.set_penalties(split.penalties)
    for _ in range(5):
        split.iterate(state)
    assert np.linalg.norm(state.w - at) < 1e-10 * np.linalg.norm(at)
    corrected, _ = split.start(np.zeros(split.shape))
    assert np.linalg.norm(converged(split, corrected) - at) < 1e-9 * np.linalg.norm(at)
