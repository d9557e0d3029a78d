"""A Spectral DiffuserCam simulator: caustic PSF, tiled spectral filter array, scenes, noise, videos.

A scene cube v (K, H, W) on the sensor window gives the measurement

    b = Σ_k F_k ⊙ crop(h ∗ v_k) + noise.

One module a part: :mod:`.spectra` (band wavelengths, band averages, analytic spectra),
:mod:`.sensor` (the pixel grid), :mod:`.caustic` (the PSF h and its autocorrelation),
:mod:`.filters` (the filter responses F_k), :mod:`.scenes` (the cubes v), :mod:`.camera`
(noise, one frame and its files), :mod:`.lenses` (lens PSFs to compare with the diffuser),
:mod:`.video` (a drifting scene, one frame per step). The names the rest of clsdcam uses are
importable from here.
"""
from ..data import shared_data_dir
from .camera import Simulation, add_noise, noiseless_measurement, simulate, write_simulation
from .caustic import autocorrelation, autocorrelation_halfwidth, caustic_psf
from .filters import filter_array
from .lenses import DESIGNS, SUPERPIXEL_PX, lens_psf
from .scenes import SCENES, make_scene
from .sensor import DEFAULT_SHAPE
from .spectra import band_average, band_wavelengths, gaussian_line
from .video import simulate_video, write_video

__all__ = [
    "DEFAULT_SHAPE", "DESIGNS", "SCENES", "SUPERPIXEL_PX", "Simulation", "add_noise", "autocorrelation",
    "autocorrelation_halfwidth", "band_average", "band_wavelengths", "caustic_psf", "filter_array", "gaussian_line",
    "lens_psf", "make_scene", "noiseless_measurement", "shared_data_dir", "simulate", "simulate_video",
    "write_simulation", "write_video",
]
