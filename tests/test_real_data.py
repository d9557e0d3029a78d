"""Real measured data beside the repository (skipped when absent): a plain DiffuserCam (K = 1,
all-ones mask) through the same code and command line, from the DiffuserCam tutorial's PSF and
raw image of a hand; also calibrated from the raw PSF frame by ``clsdcam calibrate psf``; and the
Spectral DiffuserScope's measured PSF and digitised filter curves as a simulated sweep through
``clsdcam calibrate filters`` to a reconstruction."""
import h5py
import numpy as np
import tifffile

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.camera.raw import bin_pixels
from clsdcam.camera.calibration import Calibration
from clsdcam.cli import main
from clsdcam.io import read_cube
from clsdcam.metrics import psnr
from clsdcam.camera.model import ForwardModel
from clsdcam.sim.camera import simulate
from clsdcam.sim.sweep import band_filters, sweep_of, write_sweep
from clsdcam.solve.solver import reconstruct

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


# ---- Spectral DiffuserScope: measured PSF, digitised filter curves as a sweep → calibrate filters → reconstruct --
SDS_SHAPE, SDS_BANDS, SDS_RANGE, SDS_FILTER_PX = (48, 56), 8, (386.0, 890.0), 2


def sds_camera(shared_data):
    """(PSF, sweep): the measured 550×570 PSF in 10×10 block means, its central 48×56; the 64 digitised curves
    T_f(λ) (370–890 nm, 2 nm) on the measured 8×8 layout, each filter SDS_FILTER_PX px wide:
    R(λ; y, x) = T_{layout[(y // p) mod 8, (x // p) mod 8]}(λ), as a simulated monochromator sweep."""
    psf = bin_pixels(np.load(shared_data("psf/spectraldiffuserscope_psf.npy")).astype(np.float64), 10)
    y0, x0 = ((n - m) // 2 for n, m in zip(psf.shape, SDS_SHAPE))
    curves = np.load(shared_data("spectra/spectraldiffuserscope/sfa64_transmission_digitized.npz"))
    y, x = np.indices(SDS_SHAPE) // SDS_FILTER_PX % 8
    response = np.moveaxis(curves["transmission"][curves["layout_index"][y, x]], -1, 0)
    return psf[y0:y0 + SDS_SHAPE[0], x0:x0 + SDS_SHAPE[1]], sweep_of(curves["wavelength_nm"], response)


def test_spectral_diffuserscope_sweep_calibrates_a_reconstruction(shared_data, tmp_path, capsys):
    """The filters recovered from the sweep are within 2 % of the true band integrals, and reconstruct the
    simulated measurement as well as the true filters (within 0.3 dB, above 15 dB); the same filters moved by one
    filter (a wrong calibration of the right size) fall below 15 dB."""
    psf, sweep = sds_camera(shared_data)
    true_filters = band_filters(sweep, SDS_BANDS, SDS_RANGE)
    write_sweep(tmp_path, simulate("target", SDS_SHAPE, SDS_BANDS, psf=psf, filters=true_filters), sweep)
    darks = sorted(map(str, (tmp_path / "dark").glob("*.tif")))
    assert main(["calibrate", "filters", str(tmp_path / "sweep"), "--wavelengths",
                 str(tmp_path / "sweep_wavelengths.csv"), "--power", str(tmp_path / "power.csv"), "--dark", *darks,
                 "--bands", str(SDS_BANDS), "--range", "{:g}:{:g}".format(*SDS_RANGE),
                 "--psf", str(tmp_path / "psf_calibration.h5"), "-o", str(tmp_path / "recovered.h5")]) == 0
    assert "261 frames 48×56, 370–890 nm" in capsys.readouterr().out
    recovered = Calibration.load(tmp_path / "recovered.h5")
    assert np.linalg.norm(recovered.filters - true_filters) / np.linalg.norm(true_filters) < 0.02
    wrong = Calibration(recovered.psf, np.roll(recovered.filters, SDS_FILTER_PX, axis=2), recovered.wavelengths)
    truth = read_cube(tmp_path / "truth.h5")["cube"]
    with_true, with_recovered, with_wrong = (psnr(reconstruct(tmp_path / "measurement.npy", cal, iters=100).cube, truth)
                                             for cal in (tmp_path / "calibration.h5", recovered, wrong))
    assert with_recovered > max(with_true - 0.3, 15.0) > with_wrong
