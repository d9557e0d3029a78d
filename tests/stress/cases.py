"""Stress cases for the solver: scale, precision, long runs, conditioning, divergence, bad values.

Each case runs on one backend and dtype and returns a :class:`Row` saying what happened
(stable / stopped with a reason / rejected with a message), the largest |value| and the
NaN count of the cube, and whether that outcome is the one required. ``quick`` picks the
CI sizes; ``tools/stress.py`` runs the full sizes and prints the table.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from clsdcam.camera.calibration import Calibration
from clsdcam.errors import InputError
from clsdcam.metrics import psnr
from clsdcam.sim import simulate
from clsdcam.solve.solver import Settings, Solver

SHAPE, BANDS = (24, 32), 4


@dataclass
class Row:
    case: str
    backend: str
    dtype: str
    iterations: int
    outcome: str
    max_abs: float
    nan_count: int
    passed: bool


def scene(seed=3, **kwargs):
    return simulate(scene="leds", shape=SHAPE, n_bands=BANDS, seed=seed, **kwargs)


def solve(calibration, measurement, backend, dtype, **settings):
    return Solver(calibration, backend=backend, settings=Settings(dtype=dtype, **settings)).solve(measurement)


def row(case, backend, dtype, result, passed, outcome=None) -> Row:
    cube = result.cube
    finite = cube[np.isfinite(cube)]
    return Row(case, backend, dtype, result.iterations, outcome or f"stable ({result.stop_reason})",
               float(np.abs(finite).max()) if finite.size else math.nan, int(np.isnan(cube).sum()),
               bool(passed and np.isfinite(cube).all()))


# ---- the cases ------------------------------------------------------------------------------
def scale(backend, dtype, quick=True) -> list[Row]:
    """b·s for s = 1e-8 … 1e8 gives the cube·s (weights are relative to the data)."""
    sim = scene()
    base = solve(sim.calibration, sim.measurement, backend, dtype, iters=30).cube
    rows = []
    for s in (1e-8, 1e-4, 1e4, 1e8):
        result = solve(sim.calibration, sim.measurement * s, backend, dtype, iters=30)
        error = np.linalg.norm(result.cube / s - base) / np.linalg.norm(base)
        rows.append(row(f"scale {s:g}", backend, dtype, result, error <= 1e-5, f"stable, rel. diff {error:.1e}"))
    return rows


def precision(backend, dtype, quick=True) -> list[Row]:
    """float32 against float64 after 500 iterations (100 quick): relative L2 ≤ 1e-3."""
    sim = scene()
    iters = 100 if quick else 500
    cubes = {dt: solve(sim.calibration, sim.measurement, backend, dt, iters=iters) for dt in ("float32", "float64")}
    ref = cubes["float64"].cube
    error = np.linalg.norm(cubes["float32"].cube - ref) / np.linalg.norm(ref)
    return [row("float32 vs float64", backend, "float32", cubes["float32"], error <= 1e-3, f"stable, rel. diff {error:.1e}")]


def reduction(backend, dtype, quick=True) -> list[Row]:
    """⟨x, y⟩ over 10⁷ (10⁸ full) float32 terms against an exact float64 sum: ≤ 1e-6 relative."""
    from clsdcam.backends import get_backend

    be = get_backend(backend, dtype)
    n = 10 ** 7 if quick else 10 ** 8
    host = np.random.default_rng(0).random(n, dtype=np.float32) + np.float32(0.5)
    exact = float(np.dot(host.astype(np.float64), host.astype(np.float64)))
    x = be.to_device(host)
    error = abs(be.vdot(x, x) - exact) / exact
    return [Row(f"vdot over {n:.0e} terms", backend, dtype, 0, f"rel. error {error:.1e}", float(host.max()), 0,
                error <= 1e-6)]


def long_run(backend, dtype, quick=True) -> list[Row]:
    """5 000 iterations (500 quick): finite, bounded, recorded objective never rises beyond round-off."""
    sim = scene()
    iters = 500 if quick else 5000
    result = solve(sim.calibration, sim.measurement, backend, dtype, iters=iters)
    objective = [r["objective"] for r in result.history if np.isfinite(r["objective"])]
    rise = max((b - min(objective[:i + 1])) / abs(min(objective[:i + 1])) for i, b in enumerate(objective))
    bounded = np.abs(result.cube).max() <= 100 * sim.truth.max()
    return [row(f"long run {iters}", backend, dtype, result, rise <= 1e-5 and bounded,
                f"stable, max rise {max(rise, 0):.1e}")]


def _calibration_variant(name: str, sim) -> Calibration:
    cal = sim.calibration
    h, w = SHAPE
    yy, xx = np.mgrid[:h, :w]
    if name == "near-delta PSF":
        psf = np.zeros(SHAPE)
        psf[h // 2, w // 2], psf[h // 2, w // 2 + 1] = 1.0, 0.05
        return replace(cal, psf=psf)
    if name == "very smooth PSF":
        return replace(cal, psf=np.exp(-((yy - h / 2) ** 2 + (xx - w / 2) ** 2) / (2 * 8.0 ** 2)))
    if name == "PSF with dead region":
        psf = cal.psf.copy()
        psf[:, : w // 2] = 0
        return replace(cal, psf=psf)
    filters = cal.filters.copy()
    filters[1] = 0  # a band no pixel sees
    return replace(cal, filters=filters)


CONDITIONING = ("near-delta PSF", "very smooth PSF", "PSF with dead region", "band no pixel sees")


def conditioning(backend, dtype, quick=True) -> list[Row]:
    """Odd PSFs and filters, and heavy noise: each converges (finite, non-negative) or says why it stopped."""
    sim = scene()
    iters = 100 if quick else 1000
    rows = []
    for name in CONDITIONING:
        cal = _calibration_variant(name, sim)
        result = solve(cal, sim.measurement, backend, dtype, iters=iters)
        rows.append(row(name, backend, dtype, result, result.cube.min() >= 0))
    noisy = scene(noise_var=0.1)
    result = solve(noisy.calibration, noisy.measurement, backend, dtype, iters=iters)
    rows.append(row("heavy noise (σ = 0.3 peak)", backend, dtype, result, result.cube.min() >= 0))
    return rows


def divergence(backend, dtype, quick=True) -> list[Row]:
    """A step 20× too large is detected and backed off; the run ends close to a normal one."""
    sim = scene()
    normal = solve(sim.calibration, sim.measurement, backend, dtype, iters=300)
    result = solve(sim.calibration, sim.measurement, backend, dtype, iters=300, step_scale=20.0)
    backoffs = int(result.attrs["backoffs"])
    gap = psnr(normal.cube, sim.truth) - psnr(result.cube, sim.truth)
    return [row("step 20× too large", backend, dtype, result, backoffs >= 1 and gap <= 1.0,
                f"stable after {backoffs} back-offs, PSNR gap {gap:.2f} dB")]


def non_finite(backend, dtype, quick=True) -> list[Row]:
    """NaN/Inf in measurement, PSF or mask: rejected before any work, with count and position."""
    sim = scene()
    rows = []
    for name in ("measurement", "psf", "filters"):
        bad = {"measurement": sim.measurement.copy(), "psf": sim.calibration.psf.copy(),
               "filters": sim.calibration.filters.copy()}
        bad[name].reshape(-1)[[5, 17]] = [np.nan, np.inf]
        try:
            cal = Calibration(bad["psf"], bad["filters"], sim.calibration.wavelengths, source="stress")
            solve(cal, bad["measurement"], backend, dtype, iters=5)
            outcome, passed = "accepted (wrong)", False
        except InputError as exc:
            outcome, passed = f"rejected: {exc}", "2 non-finite" in str(exc)
        rows.append(Row(f"NaN/Inf in {name}", backend, dtype, 0, outcome, math.nan, 0, passed))
    return rows


CASES = {f.__name__: f for f in (scale, precision, reduction, long_run, conditioning, divergence, non_finite)}
