"""A simulated monochromator sweep of the simulator's filter array (``clsdcam simulate DIR --sweep``), so that
the whole calibration loop — sweep → ``clsdcam calibrate filters`` → reconstruct — can be checked against the
truth.

The pixel response at wavelength λ is R(λ; y, x) = Σ_f coverage_f(y, x) · T_f(λ) (:func:`.filters.filter_array`
sampled at λ). Frame i, the monochromator at λ_i on the grid SWEEP_NM (a line narrower than the step), the
source at relative power p_i = P(λ_i) / max_j P(λ_j), in counts of 1 e⁻ each:

    c_i = clip(round(DARK + Poisson(g · p_i · R(λ_i)) + 𝒩(0, READ²)), 0, 65535)   (16-bit)

with g such that the brightest pixel of the sweep collects PEAK_COUNTS (:func:`sweep_of` makes these frames of any
response R, e.g. measured filter curves on a filter layout). P is the Cornerstone monochromator's
measured power (``spectra/spectraldiffuserscope/cornerstone_power_20240223.csv`` under
:func:`clsdcam.data.shared_data_dir`) when present, else a smooth lamp-like curve; the simulator interpolates it
linearly, as ``calibrate filters`` does. N_DARK dark frames are DARK + read noise.

The camera the sweep calibrates has the true filters of K equal bands over the prototype's 386–898 nm:
F_k = ∫_{band k} R(λ) dλ (:func:`clsdcam.calibrate.bands.integrate_bands` on the sweep's grid), scaled to max 1;
its measurement and truth are simulated with them (:func:`.camera.simulate`).

Files written: ``sweep/frame_NNNN_LLLnm.tif`` (16-bit, sorted by name = by wavelength), ``dark/dark_NN.tif``,
``sweep_wavelengths.csv`` (one column, nm), ``power.csv`` (wavelength nm, power), ``true_filters.h5``
(``filters`` (N, H, W) = R(λ_i), ``wavelength`` (N,)), ``psf_calibration.h5`` (the PSF as a one-band
calibration, as ``calibrate psf`` writes one), next to ``calibration.h5`` (the true K-band calibration),
``measurement.npy`` and ``truth.h5``.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..calibrate.bands import equal_edges, integrate_bands
from ..camera.calibration import Calibration
from ..data import missing_text, shared_data_dir
from ..io import atomic_output, write_wavelengths
from ..camera.prototype import SPECTRAL_RANGE
from .camera import Simulation, resolve_geometry, simulate, write_simulation
from .filters import filter_array

SWEEP_NM = (370.0, 898.0, 2.0)     # start, stop (included), step
DARK, READ = 400.0, 3.0            # counts: dark level, read-noise rms
PEAK_COUNTS = 40000.0              # the brightest pixel of the sweep, above the dark
FULL_SCALE = 65535                 # 16-bit frames
N_DARK = 8
CORNERSTONE = "spectra/spectraldiffuserscope/cornerstone_power_20240223.csv"


@dataclass(frozen=True, eq=False)
class SweepSimulation:
    wavelengths: np.ndarray    # (N,) nm
    response: np.ndarray       # (N, H, W) float32, R(λ_i)
    frames: np.ndarray         # (N, H, W) uint16
    darks: np.ndarray          # (N_DARK, H, W) uint16
    power: np.ndarray          # (M, 2): wavelength nm, power
    power_source: str


def sweep_grid() -> np.ndarray:
    start, stop, step = SWEEP_NM
    return start + step * np.arange(int(round((stop - start) / step)) + 1)


def power_table() -> tuple[np.ndarray, str]:
    """(wavelength nm, power) rows and where they came from: the Cornerstone CSV, else a smooth curve
    P(λ) = 2 + 3 exp(−((λ − 470)/150)²) µW every 10 nm over 350–900 nm (and why the CSV was not used)."""
    path = shared_data_dir() / CORNERSTONE
    if path.exists():
        from ..calibrate.tables import read_table

        return read_table(path, "power", 2), str(path)
    lam = np.arange(350.0, 901.0, 10.0)
    curve = np.stack([lam, 2.0 + 3.0 * np.exp(-((lam - 470.0) / 150.0) ** 2)], axis=1)
    return curve, f"a smooth lamp-like curve, {missing_text(CORNERSTONE)}"


def simulate_sweep(shape, seed: int = 0) -> SweepSimulation:
    """The sweep frames and dark frames of the module docstring (seeded), of the simulator's filter array."""
    lam = sweep_grid()
    return sweep_of(lam, filter_array(shape, lam, seed), seed)


def sweep_of(wavelengths, response, seed: int = 0) -> SweepSimulation:
    """A sweep of any pixel response R(λ_i; y, x) (N, H, W) at ``wavelengths`` (N,) nm (measured filter curves, say):
    the frames c_i and dark frames of the module docstring (seeded)."""
    lam, response = np.asarray(wavelengths, np.float64), np.asarray(response, np.float32)
    table, source = power_table()
    power = np.interp(lam, table[:, 0], table[:, 1])
    signal = power[:, None, None] / power.max() * response
    gain = PEAK_COUNTS / signal.max()
    rng = np.random.default_rng([seed, 1])
    frames = np.stack([_counts(rng, gain * s) for s in signal])
    darks = np.stack([_counts(rng, np.zeros(response.shape[1:])) for _ in range(N_DARK)])
    return SweepSimulation(lam, response, frames, darks, table, source)


def _counts(rng: np.random.Generator, electrons: np.ndarray) -> np.ndarray:
    """DARK + Poisson(electrons) + read noise, rounded and clipped to 16 bits."""
    counts = DARK + rng.poisson(electrons) + rng.normal(0.0, READ, electrons.shape)
    return np.clip(np.round(counts), 0, FULL_SCALE).astype(np.uint16)


def band_filters(sweep: SweepSimulation, n_bands: int, span=SPECTRAL_RANGE) -> np.ndarray:
    """The true filters of K equal bands over ``span`` (nm; default the prototype's range), scaled to max 1:
    (K, H, W) float32."""
    integrals = integrate_bands(sweep.wavelengths, sweep.response, equal_edges(n_bands, *span))
    return (integrals / integrals.max()).astype(np.float32)


def simulate_with_sweep(scene: str = "target", shape=None, n_bands: int | None = None, seed: int = 0,
                        **noise) -> tuple[Simulation, SweepSimulation]:
    """A frame of ``scene`` through a camera whose filters are the sweep's true band filters, and the sweep."""
    shape, n_bands = resolve_geometry(shape, n_bands, None, None)
    sweep = simulate_sweep(shape, seed)
    simulation = simulate(scene, shape, n_bands, seed, filters=band_filters(sweep, n_bands), **noise)
    return simulation, sweep


def write_sweep(outdir, simulation: Simulation, sweep: SweepSimulation) -> dict[str, Path]:
    """The files of the module docstring in ``outdir``; returns {name: path} (folders for the frames)."""
    import h5py

    outdir = Path(outdir)
    paths = write_simulation(outdir, simulation)
    paths["sweep"] = _write_frames(outdir / "sweep", [f"frame_{i:04d}_{lam:.0f}nm.tif"
                                                      for i, lam in enumerate(sweep.wavelengths)], sweep.frames)
    paths["dark"] = _write_frames(outdir / "dark", [f"dark_{i:02d}.tif" for i in range(len(sweep.darks))], sweep.darks)
    paths["sweep_wavelengths"] = _write_csv(outdir / "sweep_wavelengths.csv", sweep.wavelengths[:, None],
                                            "wavelength (nm)")
    paths["power"] = _write_csv(outdir / "power.csv", sweep.power, "wavelength (nm),power (uW)")
    with atomic_output(outdir / "true_filters.h5") as tmp, h5py.File(tmp, "w") as f:
        f["filters"] = sweep.response
        write_wavelengths(f, sweep.wavelengths)
        f.attrs["note"] = "R(λ_i; y, x): the filter array's true response at each sweep wavelength"
    paths["true_filters"] = outdir / "true_filters.h5"
    psf = simulation.calibration.psf
    Calibration(psf, np.ones((1,) + psf.shape), [550.0], source="clsdcam.sim.sweep: the PSF alone").save(
        outdir / "psf_calibration.h5")
    paths["psf_calibration"] = outdir / "psf_calibration.h5"
    return paths


def _write_frames(folder: Path, names, frames) -> Path:
    """One 16-bit TIFF a frame, named ``names``."""
    import tifffile

    for name, frame in zip(names, frames):
        with atomic_output(folder / name) as tmp:
            tifffile.imwrite(tmp, frame)
    return folder


def _write_csv(path: Path, rows: np.ndarray, header: str) -> Path:
    with atomic_output(path) as tmp:
        np.savetxt(tmp, rows, delimiter=",", header=header, comments="", fmt="%.10g")
    return path
