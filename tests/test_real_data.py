"""Real measured data beside the repository (skipped when absent): a plain DiffuserCam (K = 1,
all-ones mask) through the same code and command line, from the DiffuserCam tutorial's PSF and
raw image of a hand; also calibrated from the raw PSF frame by ``clsdcam calibrate psf``."""
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


def assert_explains(cube, psf, raw):
    """The cube, in the units of the calibration whose PSF is ``psf``, explains the raw frame (‖A v − b‖ < 25 %
    of ‖b‖) and is not a flat image."""
    model = ForwardModel(NumpyBackend("float64"), psf, np.ones((1,) + psf.shape))
    fit = model.forward(model.embed(cube))
    assert np.linalg.norm(fit - raw) < 0.25 * np.linalg.norm(raw)
    assert cube.std() > 0.1 * cube.mean()


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
    assert_explains(cube, psf, raw)


def test_calibrate_psf_then_reconstruct_the_raw_frame(shared_data, tmp_path, capsys):
    """``calibrate psf`` on the raw 1200×1600 PSF frame; ``reconstruct`` takes the raw hand frame as it is (the
    calibration's raw steps applied automatically) and the cube explains the frame after the same steps."""
    psf_path = shared_data("psf/diffusercam_tutorial_psf_sample.tif")
    raw_path = shared_data("psf/diffusercam_tutorial_rawdata_hand_sample.tif")
    assert main(["calibrate", "psf", str(psf_path), "--dark-corner", "10", "--bin", "4",
                 "-o", str(tmp_path / "cal.h5")]) == 0
    assert "dark 34.08 (corner patch [5:15, 5:15])" in capsys.readouterr().out
    assert main(["reconstruct", str(raw_path), "--calibration", str(tmp_path / "cal.h5"),
                 "-o", str(tmp_path / "hand.h5"), "--iters", "60", "--quiet"]) == 0
    with h5py.File(tmp_path / "hand.h5", "r") as f:
        cube, source = f["cube"][...], f.attrs["calibration"]
    assert cube.shape == (1, 300, 400) and "raw steps applied to the measurement" in source
    dark = tifffile.imread(psf_path)[5:15, 5:15].mean()  # the steps by hand: dark, clip at 0, 4×4 block means

    def steps(path):
        return np.maximum(tifffile.imread(path) - dark, 0).reshape(300, 4, 400, 4).mean(axis=(1, 3))

    psf = steps(psf_path) / np.linalg.norm(steps(psf_path))
    np.testing.assert_allclose(Calibration.load(tmp_path / "cal.h5").psf, psf, atol=1e-6)
    assert_explains(cube, psf, steps(raw_path))
