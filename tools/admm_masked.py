"""ADMM's c-step with the data split's unobserved part eliminated: measured as ``bench_converged --variants`` (names
``masked``, the conjugate-gradient steps a c-step takes, and ``coarse``, the grid they are taken on) and not built
into the solver (docs/convergence.md, "Where the road left lies", has the numbers).

ADMM splits x = Hv over the whole field, so that its c-step is diagonal in Fourier (Almeida and Figueiredo 2013's
masked deconvolution). Outside the sensor window no data bind x: the x-step leaves x = Hv + ξ with ξ = 0 there, and
the next c-step's μ₁/2‖Hv − (x − ξ)‖² over that region pulls Hv back towards its last value, an inertia on light
that the PSF spreads nearly alike from the window and the field's margin. Minimised over x outside the window as well
as over v, that term vanishes, and the c-step becomes the masked system (M the window)

    A v = (μ₁HᵀMH + μ₂ΣD_dᵀD_d + μ₃I) v = μ₁HᵀM(x − ξ) + rest,   A = P − μ₁Hᵀ(I − M)H,

where P = μ₁HᵀH + μ₂ΣD_dᵀD_d + μ₃I is today's c-step matrix, solved exactly in Fourier (:mod:`clsdcam.algorithms.
admm.terms`). The variant starts from today's c-step, v₀ = P⁻¹(μ₁Hᵀ(x − ξ) + rest) with x − ξ over the field, whose
residual in the masked system is r₀ = μ₁Hᵀ(I − M)(Hv₀ − (x − ξ)), and takes N steps of conjugate gradients
preconditioned by P⁻¹, in Fourier (half spectra, their inner products weighted for the columns they stand for). The
correction δ then goes to v and, relaxed, to the data split's x − ξ (Ŷ += αĤδ̂ and its window). The fixed point is
the same problem's minimiser. Each step costs 2K transforms over the field, the start 4K and the correction 2K more:
a variant's times measure this script, not what a built c-step would cost. ``coarse=f`` takes the steps on a grid f
times coarser along y and x instead: the residual's lowest frequencies (Hv₀ − (x − ξ) in Fourier, where a built
c-step has both), A and P⁻¹ there with the field's own Fourier values, the window's coarse pixels as the mask, and the
correction zero-padded back; what moves slowly is smooth light (docs/convergence.md), and a step there costs 2K
transforms f² times smaller. Host steps only (``--backend numpy``).
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import astuple

import numpy as np
import scipy.fft

MASKED_VARIANTS = ("masked", "coarse")


def low_band(spectrum: np.ndarray, shape) -> np.ndarray:
    """The lowest frequencies of a half spectrum (…, Hp, Wp//2 + 1): those of an (h, w) grid's, h even."""
    h, w = shape
    top, columns = spectrum.shape[-2] - h // 2, slice(0, w // 2 + 1)
    return np.concatenate([spectrum[..., :h // 2, columns], spectrum[..., top:, columns]], axis=-2)


def widened(spectrum: np.ndarray, shape) -> np.ndarray:
    """A coarse grid's half spectrum zero-padded to the (Hp, Wp) field's (the inverse of :func:`low_band`)."""
    (hp, wp), h = shape, spectrum.shape[-2]
    out = np.zeros(spectrum.shape[:-2] + (hp, wp // 2 + 1), spectrum.dtype)
    out[..., :h // 2, :spectrum.shape[-1]] = spectrum[..., :h // 2, :]
    out[..., hp - h // 2:, :spectrum.shape[-1]] = spectrum[..., h // 2:, :]
    return out


class MaskedSystem:
    """A and P⁻¹ of one splitting's penalties, in Fourier over the half spectrum (float64) of the field, or with
    ``factor`` f > 1 of a grid f times coarser along y and x: the field's lowest frequencies, where A and P keep the
    field's own values (the mask then the window's coarse pixels)."""

    def __init__(self, split, factor: int = 1):
        from clsdcam.algorithms.admm.terms import band_coupling, band_degrees, band_diagonal, band_pivots

        p, (hp, wp), (h, w) = split.penalties, split.field_shape, split.sensor_shape
        if hp % (2 * factor) or wp % (2 * factor):
            raise ValueError(f"a field of {hp}×{wp} has no even grid {factor} times coarser")
        self.factor, self.field_shape = factor, (hp, wp)
        self.shape, self.window = (hp // factor, wp // factor), (h // factor, w // factor)
        transfer = split.transfer.astype(np.complex128)
        diagonal = band_diagonal(p, split.axes, np.abs(transfer) ** 2, (hp, wp))
        self.full_transfer, self.data = transfer, p.data
        self.transfer, self.diagonal = low_band(transfer, self.shape), low_band(diagonal, self.shape)
        self.coupling = band_coupling(p, split.axes)
        self.degrees = band_degrees(split.n_bands)[:, None, None]
        self.pivots = band_pivots(self.diagonal, self.coupling, split.n_bands)
        self.weights = np.full(self.shape[1] // 2 + 1, 2.0)
        self.weights[0] = self.weights[-1] = 1.0

    def dot(self, a: np.ndarray, b: np.ndarray) -> float:
        """⟨a, b⟩ of the real fields whose half spectra a and b are (up to the transform's constant)."""
        return float(np.sum(self.weights * np.real(np.conj(a) * b)))

    def outside(self, field: np.ndarray) -> np.ndarray:
        """(I − M)·field: ``field`` with its sensor window set to 0 (in place)."""
        h, w = self.window
        field[:, :h, :w] = 0
        return field

    def pulled(self, field: np.ndarray) -> np.ndarray:
        """μ₁Hᵀ(I − M)·field, in Fourier (``field`` is spent)."""
        return self.data * np.conj(self.transfer) * scipy.fft.rfft2(self.outside(field))

    def apply(self, v: np.ndarray) -> np.ndarray:
        """A·v̂ = P·v̂ − μ₁Hᵀ(I − M)H·v̂."""
        e = self.coupling
        out = (self.diagonal + e * self.degrees) * v
        out[1:] -= e * v[:-1]
        out[:-1] -= e * v[1:]
        return out - self.pulled(scipy.fft.irfft2(self.transfer * v, s=self.shape))

    def precondition(self, r: np.ndarray) -> np.ndarray:
        """P⁻¹·r̂ by the solve along λ's own Thomas sweeps (:func:`clsdcam.algorithms.admm.host_steps.sweep_bands`)."""
        from clsdcam.algorithms.admm.host_steps import sweep_bands

        return sweep_bands(r.copy(), self.pivots, self.coupling, {})

    def correction(self, r: np.ndarray, steps: int) -> np.ndarray:
        """δ̂ after ``steps`` of P⁻¹-preconditioned conjugate gradients on A·δ̂ = r̂ from 0."""
        delta, z = np.zeros_like(r), self.precondition(r)
        p, rz = z.copy(), self.dot(r, z)
        for _ in range(steps):
            ap = self.apply(p)
            step = rz / self.dot(p, ap)
            delta += step * p
            r = r - step * ap
            z = self.precondition(r)
            rz, last = self.dot(r, z), rz
            p = z + (rz / last) * p
        return delta


def masked_c_step(split, state, steps: int, plain, factor: int = 1) -> None:
    """Today's c-step (``plain``), then ``steps`` conjugate-gradient steps towards the masked system's solution
    (the module docstring), on a grid ``factor`` times coarser than the field (the residual's lowest frequencies in,
    the correction zero-padded out)."""
    key = (astuple(split.penalties), tuple(split.axes), factor)
    if getattr(split, "_masked", (None,))[0] != key:
        split._masked = (key, MaskedSystem(split, factor))
    system, f = split._masked[1], split._masked[1].factor
    data = state.data_spectrum.astype(np.complex128)                      # x − ξ (its window's change still in hv)
    plain(split, state)
    apart = system.full_transfer * scipy.fft.rfft2(state.v.astype(np.float64)) - data      # Hv₀ − (x − ξ)
    field = scipy.fft.irfft2(low_band(apart, system.shape) / f ** 2, s=system.shape)
    delta = widened(system.correction(system.pulled(field), steps), system.field_shape) * f ** 2
    h, w = split.sensor_shape
    state.v += scipy.fft.irfft2(delta, s=system.field_shape).astype(state.v.dtype)
    moved = split.relaxation * system.full_transfer * delta
    state.data_spectrum += moved.astype(state.data_spectrum.dtype)
    state.hv += scipy.fft.irfft2(moved, s=system.field_shape)[:, :h, :w].astype(state.hv.dtype)


@contextmanager
def masked_c_steps(variant: dict):
    """While it lasts, ADMM's host c-step is :func:`masked_c_step` with ``variant["masked"]`` steps on a grid
    ``variant["coarse"]`` times coarser (1: the field's; as built where the variant names no steps); restored after."""
    from clsdcam.algorithms.admm.host_steps import Splitting

    plain = Splitting.c_step
    steps, factor = int(variant.get("masked", 0)), int(variant.get("coarse", 1))
    if steps:
        Splitting.c_step = lambda split, state: masked_c_step(split, state, steps, plain, factor)
    try:
        yield
    finally:
        Splitting.c_step = plain
