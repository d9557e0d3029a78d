"""Short simulated videos for batches: a scene drifting across the sensor, one noisy frame per step.

Frame t shows the scene translated by t·(vy, vx) pixels (bilinear, zero fill),

    v(t)(y, x) = v(0)(y − t·vy, x − t·vx),   b(t) = max(Σ_k F_k ⊙ crop(h ∗ v(t)_k) + noise_t, 0),

through one camera (PSF, filters) with fresh noise per frame (seed + t). Written as
``frames.npy`` (N, H, W), ``truth.h5`` (``cubes`` (N, K, H, W) with the dimension scales of a batch output's, ``frame``,
``wavelength`` (nm), ``y``, ``x``) and ``calibration.h5``.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.ndimage as ndi

from ..camera.calibration import Calibration
from ..io import atomic_output, write_scaled
from .camera import add_noise, noiseless_measurement
from .caustic import caustic_psf
from .filters import filter_array
from .scenes import make_scene
from .sensor import DEFAULT_SHAPE
from .spectra import band_wavelengths

DRIFT = {"leds": (0.0, 1.0)}      # px per frame (y, x): a drifting LED grid; other scenes translate by DEFAULT_DRIFT
DEFAULT_DRIFT = (0.5, 0.5)


def simulate_video(scene: str = "leds", n_frames: int = 8, shape=DEFAULT_SHAPE, n_bands: int = 64,
                   seed: int = 0, noise_var: float = 1e-5, photons: float | None = 20000.0, drift=None):
    """(calibration, frames (N, H, W) float32, truth (N, K, H, W) float32); ``drift`` (vy, vx) px per frame, by
    default the scene's (DRIFT)."""
    wavelengths = band_wavelengths(n_bands)
    psf = caustic_psf(shape, seed)
    filters = filter_array(shape, wavelengths, seed)
    first = make_scene(scene, shape, wavelengths, seed)
    vy, vx = drift if drift is not None else DRIFT.get(scene, DEFAULT_DRIFT)
    truth = np.stack([ndi.shift(first, (0, t * vy, t * vx), order=1) for t in range(n_frames)]).astype(np.float32)
    frames = np.stack([
        np.maximum(add_noise(noiseless_measurement(psf, filters, cube), np.random.default_rng(seed + t),
                             noise_var, photons), 0)
        for t, cube in enumerate(truth)]).astype(np.float32)
    return Calibration(psf, filters, wavelengths, source=f"clsdcam.sim.video(scene={scene!r}, seed={seed})"), frames, truth


def write_video(outdir, calibration, frames, truth) -> dict[str, Path]:
    """``calibration.h5``, ``frames.npy``, ``truth.h5`` in ``outdir``; returns their paths."""
    import h5py

    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    paths = {"calibration": outdir / "calibration.h5", "frames": outdir / "frames.npy", "truth": outdir / "truth.h5"}
    calibration.save(paths["calibration"])
    with atomic_output(paths["frames"]) as tmp, open(tmp, "wb") as f:
        np.save(f, frames)
    with atomic_output(paths["truth"]) as tmp, h5py.File(tmp, "w") as f:
        write_scaled(f, "cubes", truth, calibration.wavelengths)
    return paths
