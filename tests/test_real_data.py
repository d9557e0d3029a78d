"""Real measured data beside the repository (skipped when absent): a plain DiffuserCam (K = 1,
all-ones mask) through the same code and command line, from the DiffuserCam tutorial's PSF and
raw image of a hand."""
import h5py
import numpy as np
import tifffile

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.calibration import Calibration
from clsdcam.cli import main
from clsdcam.model import ForwardModel

FACTOR = 8  # 1200×1600 → 150×200, as the tutorial downsamples by powers of two


def downsampled(path) -> np.ndarray:
    """Dark-corner mean subtracted (as the tutorial does), then FACTOR×FACTOR block means."""
    image = tifffile.imread(path).astype(np.float64)
    image -= image[5:15, 5:15].mean()
    h, w = image.shape[0] // FACTOR, image.shape[1] // FACTOR
    return image[:h * FACTOR, :w * FACTOR].reshape(h, FACTOR, w, FACTOR).mean(axis=(1, 3))


def test_plain_diffusercam_k1_through_the_cli(shared_data, tmp_path):
    psf = np.maximum(downsampled(shared_data("psf/diffusercam_tutorial_psf_sample.tif")), 0)
    raw = np.maximum(downsampled(shared_data("psf/diffusercam_tutorial_rawdata_hand_sample.tif")), 0)
    Calibration(psf, np.ones((1,) + psf.shape), [550.0], source="tutorial").save(tmp_path / "cal.h5")
    tifffile.imwrite(tmp_path / "raw.tif", raw.astype(np.float32))
    assert main(["reconstruct", str(tmp_path / "raw.tif"), "--calibration", str(tmp_path / "cal.h5"),
                 "-o", str(tmp_path / "hand.h5"), "--iters", "60", "--quiet"]) == 0
    with h5py.File(tmp_path / "hand.h5", "r") as f:
        cube = f["cube"][...]
    assert cube.shape == (1, 150, 200) and cube.min() >= 0 and np.isfinite(cube).all()
    model = ForwardModel(NumpyBackend("float64"), psf / np.linalg.norm(psf), np.ones((1,) + psf.shape))
    fit = model.forward(model.embed(cube))
    assert np.linalg.norm(fit - raw) < 0.25 * np.linalg.norm(raw)   # the cube explains the raw frame
    assert cube.std() > 0.1 * cube.mean()                           # and is not a flat image
