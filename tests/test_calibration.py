"""Calibration files (MATLAB v5, v7.3, our HDF5) and the preprocessing steps."""
import h5py
import numpy as np
import pytest
import scipy.io

from clsdcam.camera.calibration import Calibration, PixelMask, Preprocessing, parse_crop, preprocess, zero_defect_block
from clsdcam.errors import InputError
from clsdcam.io import load_measurement

RNG = np.random.default_rng(7)
H, W, K = 9, 13, 4
PSF = RNG.random((H, W))
MASK = RNG.random((H, W, K))  # the paper's (H, W, K)
WAVS = np.linspace(400, 700, K)[None, :]


def write_v73(path, psf=PSF, mask=MASK, wavs=WAVS):
    """A MATLAB v7.3 file as MATLAB writes it: HDF5, arrays transposed, MATLAB_class attributes."""
    with h5py.File(path, "w", userblock_size=512) as f:
        for key, value in (("psf", psf), ("mask", mask), ("wavs", wavs)):
            f[key] = np.asarray(value).T
            f[key].attrs["MATLAB_class"] = np.bytes_("double")
    with open(path, "r+b") as f:
        f.write(b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Sun Nov 22 2026 HDF5 schema 1.00 .")


def check(cal):
    np.testing.assert_array_equal(cal.psf, PSF)
    np.testing.assert_array_equal(cal.filters, np.moveaxis(MASK, -1, 0))
    np.testing.assert_array_equal(cal.wavelengths, WAVS.ravel())


def test_loads_matlab_v5(tmp_path):
    scipy.io.savemat(tmp_path / "calibration.mat", {"psf": PSF, "mask": MASK, "wavs": WAVS})
    check(Calibration.load(tmp_path / "calibration.mat"))


def test_loads_matlab_v73(tmp_path):
    write_v73(tmp_path / "calibration.mat")
    check(Calibration.load(tmp_path / "calibration.mat"))


def test_our_hdf5_round_trip(tmp_path):
    cal = Calibration(PSF, np.moveaxis(MASK, -1, 0), WAVS)
    cal.save(tmp_path / "cal.h5")
    back = Calibration.load(tmp_path / "cal.h5")
    np.testing.assert_allclose(back.filters, cal.filters, rtol=1e-7)
    np.testing.assert_allclose(back.psf, cal.psf, rtol=1e-7)
    assert back.n_bands == K and back.shape == (H, W)


def test_single_band_mask_without_trailing_axis(tmp_path):
    scipy.io.savemat(tmp_path / "c.mat", {"psf": PSF, "mask": np.ones((H, W)), "wavs": [[550.0]]})
    cal = Calibration.load(tmp_path / "c.mat")
    assert cal.filters.shape == (1, H, W) and cal.wavelengths.tolist() == [550.0]


@pytest.mark.parametrize("contents, message", [
    ({"psf": PSF, "wavs": WAVS}, "missing mask"),
    ({"psf": PSF, "mask": MASK[:-1], "wavs": WAVS}, "do not match psf"),
    ({"psf": PSF, "mask": MASK, "wavs": WAVS[:, :-1]}, "3 wavelengths for 4 bands"),
    ({"psf": 0 * PSF, "mask": MASK, "wavs": WAVS}, "psf is all zeros"),
    ({"psf": np.where(PSF > 0.9, np.nan, PSF), "mask": MASK, "wavs": WAVS}, "non-finite"),
    ({"psf": PSF, "mask": MASK, "wavs": np.array([["a", "b", "c", "d"]])}, "missing wavs"),
])
def test_bad_calibrations_name_the_problem(tmp_path, contents, message):
    scipy.io.savemat(tmp_path / "bad.mat", contents)
    with pytest.raises(InputError, match=message) as info:
        Calibration.load(tmp_path / "bad.mat")
    assert "bad.mat" in str(info.value)


@pytest.mark.parametrize("content", [b"", b"MATLAB 5.0 MAT-file truncated", b"\x89HDF\r\n\x1a\n\x00\x00", b"garbage" * 20])
def test_empty_truncated_and_garbage_files(tmp_path, content):
    path = tmp_path / "c.mat"
    path.write_bytes(content)
    with pytest.raises(InputError, match="c.mat"):
        Calibration.load(path)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        Calibration.load(tmp_path / "absent.mat")


def test_preprocessing_steps_each_do_their_job():
    filters = np.moveaxis(MASK, -1, 0) * 3.0
    filters[:, 4, 6] = 10.0  # the over-bright defect
    cal = Calibration(PSF * 5, filters, WAVS)
    b = RNG.random((H, W))
    out, b2 = preprocess(cal, b, Preprocessing(zero_defect=True, drop_last_band=True))
    assert out.n_bands == K - 1 and out.wavelengths.tolist() == WAVS.ravel()[:-1].tolist()
    assert np.linalg.norm(out.psf) == pytest.approx(1.0) and out.filters.max() == pytest.approx(1.0)
    assert not out.filters[:, 2:6, 4:8].any() and not b2[2:6, 4:8].any()
    assert b2[0, 0] == b[0, 0] and cal.filters[0, 4, 6] == 10.0  # inputs untouched
    kept, _ = preprocess(cal, b, Preprocessing(normalize_psf=False, normalize_filters=False))
    np.testing.assert_array_equal(kept.psf, cal.psf)
    np.testing.assert_array_equal(kept.filters, cal.filters)


def test_crop_applies_to_both_and_checks_bounds():
    cal = Calibration(PSF, np.moveaxis(MASK, -1, 0), WAVS)
    out, b = preprocess(cal, np.arange(H * W, dtype=float).reshape(H, W), Preprocessing(crop=(1, 5, 2, 9)))
    assert out.shape == (4, 7) and b.shape == (4, 7) and b[0, 0] == W + 2
    with pytest.raises(InputError, match="outside the calibration"):
        preprocess(cal, np.zeros((H, W)), Preprocessing(crop=(0, H + 1, 0, 3)))
    with pytest.raises(InputError, match="give --crop"):
        preprocess(cal, np.zeros((H + 2, W)), Preprocessing())


def test_dead_pixels_are_excluded_and_preprocessing_is_hashable():
    cal = Calibration(PSF, np.moveaxis(MASK, -1, 0), WAVS)
    mask = np.zeros((H, W))
    mask[2, 3] = mask[7, 1] = 1
    dead = PixelMask.of(mask)
    assert dead.pixels == ((2, 3), (7, 1)) and np.array_equal(dead.array(), mask != 0)
    options = Preprocessing(dead_pixels=dead)
    assert options == Preprocessing(dead_pixels=PixelMask.of(mask)) and hash(options) == hash(Preprocessing(dead_pixels=dead))
    out, b = preprocess(cal, np.ones((H, W)), options)
    assert b[2, 3] == 0 and b[7, 1] == 0 and b.sum() == H * W - 2
    assert not out.filters[:, 2, 3].any() and out.filters[:, 2, 4].all()
    with pytest.raises(InputError, match="dead-pixel mask"):
        preprocess(cal, np.ones((H, W)), Preprocessing(dead_pixels=PixelMask.of(np.ones((H, W + 1)))))


def test_parse_crop():
    assert parse_crop("100:420,80:540") == (100, 420, 80, 540)
    for bad in ("1:2", "a:b,c:d", "5:1,0:3", "1:2,3"):
        with pytest.raises(InputError):
            parse_crop(bad)


def test_defect_block_at_the_border_is_clipped():
    filters = np.ones((2, 6, 6))
    filters[:, 0, 0] = 5
    f, b = zero_defect_block(filters, np.ones((6, 6)))
    assert not f[:, :2, :2].any() and f[:, 2:, 2:].all() and b.sum() == 32


def test_real_thordog_frame_with_reference_crop(shared_data):
    frame = load_measurement(shared_data("psf/spectral_diffusercam_meas_thordog.png"))
    assert frame.shape == (494, 659) and frame.max() > 0
    cal = Calibration(np.ones((494, 659)), np.ones((3, 494, 659)), [450.0, 550.0, 650.0])
    out, b = preprocess(cal, frame, Preprocessing.reference())
    assert b.shape == (320, 460) and out.filters.shape == (2, 320, 460)


@pytest.mark.parametrize("compress", [False, True])
def test_matlab_v5_reader_matches_scipy_on_mixed_content(tmp_path, compress):
    """Our bounds-checked v5 reader against scipy's on numeric classes, a string and a cell to skip."""
    from clsdcam.io import MAX_DATASET_BYTES
    from clsdcam.matv5 import read_mat_v5

    contents = {"psf": PSF, "mask": MASK.astype(np.float32), "wavs": WAVS.astype(np.uint16),
                "ints": np.arange(-3, 9, dtype=np.int8).reshape(3, 4), "note": "text", "cell": np.array([1, "a"], dtype=object)}
    scipy.io.savemat(tmp_path / "m.mat", contents, do_compression=compress)
    ours = read_mat_v5((tmp_path / "m.mat").read_bytes(), MAX_DATASET_BYTES)
    reference = scipy.io.loadmat(tmp_path / "m.mat")
    assert sorted(ours) == ["ints", "mask", "psf", "wavs"]
    for key, value in ours.items():
        np.testing.assert_array_equal(value, reference[key].astype(np.float64))
