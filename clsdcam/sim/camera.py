"""The whole camera: one simulated Spectral DiffuserCam frame, with noise, and its files.

The camera (Monakhova et al., Optica 2020): a bare sensor under an 8×8 tile of 64
narrow-band filters (each ``filter_px`` × ``filter_px`` pixels, 386–898 nm) and a smooth
random diffuser whose caustic pattern is the PSF h. A scene cube v (K, H, W) on the sensor
window gives the measurement

    b = Σ_k F_k ⊙ crop(h ∗ v_k) + noise,

computed with :class:`clsdcam.camera.model.ForwardModel` (PSF origin at its centre pixel); the noise
is shot noise then Gaussian read noise (:func:`add_noise`). Filter responses are sampled at
the band wavelengths, F_k = T(λ_k). Every random choice is seeded; the same arguments give
the same arrays.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from ..backends import NumpyBackend
from ..camera.calibration import Calibration
from ..errors import InputError
from ..io import atomic_output, save_measurement, write_scaled
from ..camera.model import ForwardModel
from .caustic import caustic_psf
from .filters import filter_array
from .scenes import make_scene
from .sensor import DEFAULT_SHAPE
from .spectra import DEFAULT_BANDS, band_wavelengths


def add_noise(b: np.ndarray, rng: np.random.Generator, gaussian_var: float = 0.0, photons: float | None = None) -> np.ndarray:
    """Shot noise, then read noise, in units of the measurement's peak m = max(b):

        b ← (m / N) · Poisson(N · max(b, 0) / m)   N = ``photons`` at the peak (None: no shot noise)
        b ← b + m · ε,  ε ~ 𝒩(0, gaussian_var)      (variance relative to m², i.e. of b/m; 0: none)

    An all-zero b is returned unchanged. The result may be negative (clip it if needed).
    """
    peak = float(np.max(b))
    noisy = np.asarray(b, dtype=np.float64)
    if peak <= 0.0:
        return noisy
    if photons is not None:
        noisy = rng.poisson(np.maximum(noisy, 0.0) / peak * photons) * (peak / photons)
    if gaussian_var > 0.0:
        noisy = noisy + rng.normal(0.0, np.sqrt(gaussian_var) * peak, noisy.shape)
    return noisy


@dataclass
class Simulation:
    calibration: Calibration    # psf (H, W), filters (K, H, W), wavelengths (K,)
    measurement: np.ndarray     # (H, W) float32 ≥ 0
    truth: np.ndarray           # (K, H, W) float32, the scene on the sensor window
    scene: str
    seed: int


def resolve_geometry(shape, n_bands, psf, filters) -> tuple[tuple[int, int], int]:
    """(H, W) and K from the arguments: given arrays win over the defaults; conflicts are InputErrors."""
    given_shape = psf.shape if psf is not None else (filters.shape[-2:] if filters is not None else None)
    if shape is not None and given_shape is not None and tuple(shape) != tuple(given_shape):
        raise InputError(f"shape {tuple(shape)} differs from the given psf/filters {tuple(given_shape)}")
    if n_bands is not None and filters is not None and n_bands != filters.shape[0]:
        raise InputError(f"n_bands {n_bands} differs from the given filters' {filters.shape[0]} bands")
    resolved_shape = tuple(given_shape or shape or DEFAULT_SHAPE)
    resolved_bands = filters.shape[0] if filters is not None else (n_bands or DEFAULT_BANDS)
    return resolved_shape, resolved_bands


def noiseless_measurement(psf: np.ndarray, filters: np.ndarray, cube: np.ndarray) -> np.ndarray:
    """b = Σ_k F_k ⊙ crop(h ∗ v_k) through :class:`ForwardModel` (float32 NumPy backend)."""
    model = ForwardModel(NumpyBackend("float32"), psf, filters)
    return model.backend.to_host(model.forward(model.embed(cube)))


def simulate(scene: str = "target", shape=None, n_bands: int | None = None, seed: int = 0,
             noise_var: float = 1e-5, photons: float | None = 20000.0,
             psf: np.ndarray | None = None, filters: np.ndarray | None = None,
             cube: np.ndarray | None = None) -> Simulation:
    """Simulate one Spectral DiffuserCam frame.

    shape (default 320 × 448) and n_bands (default 64) come from ``psf``/``filters`` when
    those are given. The PSF is :func:`caustic_psf`, the filters :func:`filter_array` at
    :func:`band_wavelengths`, all seeded by ``seed``. Noise (see :func:`add_noise`): shot
    noise at ``photons`` at the peak (default 20 000, a small pixel's full well), then
    Gaussian read noise of variance ``noise_var`` relative to the peak² (default 1e-5,
    σ ≈ 0.3 % of the peak); the measurement is clipped at 0. ``cube``: a (K, H, W) scene to image instead of
    the named one (e.g. :func:`clsdcam.sim.kinds.make_kind`'s; ``scene`` then only names it).
    """
    shape, n_bands = resolve_geometry(shape, n_bands, psf, filters)
    wavelengths = band_wavelengths(n_bands)
    psf = caustic_psf(shape, seed) if psf is None else np.asarray(psf, dtype=np.float32)
    filters = filter_array(shape, wavelengths, seed) if filters is None else np.asarray(filters, dtype=np.float32)
    truth = make_scene(scene, shape, wavelengths, seed) if cube is None else np.asarray(cube, np.float32)
    if truth.shape != (n_bands,) + tuple(shape):
        raise InputError(f"cube {truth.shape}: expected {(n_bands,) + tuple(shape)} (bands, height, width)")
    clean = noiseless_measurement(psf, filters, truth)
    noisy = add_noise(clean, np.random.default_rng(seed), noise_var, photons)
    measurement = np.maximum(noisy, 0.0).astype(np.float32)
    calibration = Calibration(psf, filters, wavelengths, source=f"clsdcam.sim(scene={scene!r}, seed={seed})")
    return Simulation(calibration, measurement, truth, scene, seed)


def write_truth(path: Path, truth: np.ndarray, wavelengths: np.ndarray) -> None:
    """HDF5 with ``cube`` (K, H, W) float32 and its dimension scales, ``wavelength`` (K,) in nm among them, as a
    reconstructed cube has them (:func:`clsdcam.io.write_scaled`), written to a temp file then renamed."""
    with atomic_output(path) as tmp, h5py.File(tmp, "w") as f:
        write_scaled(f, "cube", truth.astype(np.float32), wavelengths)


def write_simulation(outdir, sim: Simulation) -> dict[str, Path]:
    """``calibration.h5``, ``measurement.npy`` and ``truth.h5`` in ``outdir`` (created); returns their paths."""
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = {name: outdir / name for name in ("calibration.h5", "measurement.npy", "truth.h5")}
    sim.calibration.save(paths["calibration.h5"])
    save_measurement(paths["measurement.npy"], sim.measurement)
    write_truth(paths["truth.h5"], sim.truth, sim.calibration.wavelengths)
    return {"calibration": paths["calibration.h5"], "measurement": paths["measurement.npy"], "truth": paths["truth.h5"]}
