"""``clsdcam calibrate``: lab frames → a calibration, step by step against hand-computed values, the remembered
raw steps, the simulated sweep → calibrate filters → reconstruct loop, and bad input (exit 2, one line,
nothing written)."""
import json
from dataclasses import replace

import h5py
import numpy as np
import pytest
import tifffile

from clsdcam.calibrate.bands import band_centres, equal_edges, integrate_bands
from clsdcam.calibrate.dark import corner_level, resolve_dark
from clsdcam.calibrate.defects import find_defects
from clsdcam.calibrate.frames import average_frames, open_sweep
from clsdcam.calibrate.psf import calibrate_psf, centroid_of
from clsdcam.camera.raw import RawSteps, apply_raw_steps, bin_pixels, read_record, shift_image, write_record
from clsdcam.calibrate.sweep import power_weights, sweep_wavelengths
from clsdcam.calibrate.measurement import prepare
from clsdcam.camera.calibration import Calibration, Preprocessing, preprocess
from clsdcam.cli import main
from clsdcam.errors import InputError


def save(path, array):
    np.save(path, np.asarray(array))
    return str(path)


# ---- frames and dark --------------------------------------------------------------------------------
def test_frames_are_averaged_and_mixed_sizes_refused(tmp_path):
    a, b = save(tmp_path / "a.npy", np.full((4, 5), 2.0)), save(tmp_path / "b.npy", np.full((4, 5), 6.0))
    mean, code = average_frames([a, b])
    np.testing.assert_array_equal(mean, np.full((4, 5), 4.0))
    assert code is None                 # float frames: no saturation code
    with pytest.raises(InputError, match="mixed sizes"):
        average_frames([a, save(tmp_path / "c.npy", np.zeros((4, 6)))])


def test_dark_corner_is_the_patch_n_half_in_from_the_corner():
    frame = np.zeros((40, 40))
    frame[5:15, 5:15] = 7.0             # the tutorial's psf[5:15, 5:15] for N = 10
    frame[:5, :] = frame[:, :5] = 1000.0
    assert corner_level(frame, 10) == 7.0
    frame[1:4, 1:4] = np.arange(9.0).reshape(3, 3)            # N = 3: rows and columns 1 … 3
    assert corner_level(frame, 3) == 4.0
    with pytest.raises(InputError, match="does not fit"):
        corner_level(frame, 30)


def test_dark_level_files_and_none(tmp_path):
    frame = np.ones((3, 4))
    assert resolve_dark(["12.5"], None, frame)[:2] == (12.5, None)
    assert resolve_dark(None, None, frame)[:2] == (0.0, None)
    darks = [save(tmp_path / f"d{i}.npy", np.full((3, 4), v)) for i, v in enumerate((1.0, 3.0))]
    level, dark, text = resolve_dark(darks, None, frame)
    assert level == 0.0 and "mean of 2 dark frames" in text
    np.testing.assert_array_equal(dark, np.full((3, 4), 2.0))
    with pytest.raises(InputError, match="the frames are 2×2"):
        resolve_dark(darks, None, np.ones((2, 2)))


# ---- raw steps ------------------------------------------------------------------------------------
def test_dark_frames_are_read_once_until_they_change(tmp_path):
    """A batch subtracts the same dark from every frame: read once, read-only, read again when a file changes."""
    frame, darks = np.ones((3, 4)), [save(tmp_path / f"d{i}.npy", np.full((3, 4), v)) for i, v in enumerate((1.0, 3.0))]
    first, again = resolve_dark(darks, None, frame)[1], resolve_dark(darks, None, frame)[1]
    assert again is first and not first.flags.writeable
    save(tmp_path / "d1.npy", np.full((3, 4), 5.0, np.float32))        # another dtype: another size on disk
    np.testing.assert_array_equal(resolve_dark(darks, None, frame)[1], np.full((3, 4), 3.0))


def test_bin_means_blocks_and_drops_the_ragged_edge():
    image = np.arange(5 * 7, dtype=float).reshape(5, 7)
    expected = [[(0 + 1 + 7 + 8) / 4, (2 + 3 + 9 + 10) / 4, (4 + 5 + 11 + 12) / 4],
                [(14 + 15 + 21 + 22) / 4, (16 + 17 + 23 + 24) / 4, (18 + 19 + 25 + 26) / 4]]
    np.testing.assert_array_equal(bin_pixels(image, 2), expected)


def test_shift_moves_content_and_fills_zeros():
    image = np.arange(1, 10, dtype=float).reshape(3, 3)
    np.testing.assert_array_equal(shift_image(image, (1, -1)), [[0, 0, 0], [2, 3, 0], [5, 6, 0]])


def test_raw_steps_in_order_dark_clip_crop_bin_shift():
    frame = np.arange(6 * 8, dtype=float).reshape(6, 8)
    steps = RawSteps((6, 8), dark_level=10.0, crop=(1, 5, 2, 8), bin=2, shift=(0, 1))
    cropped = np.maximum(frame - 10.0, 0)[1:5, 2:8]           # rows 1–4, columns 2–7; values 0 below the dark
    binned = cropped.reshape(2, 2, 3, 2).mean(axis=(1, 3))
    expected = np.zeros_like(binned)
    expected[:, 1:] = binned[:, :-1]
    np.testing.assert_array_equal(apply_raw_steps(steps, frame), expected)
    with pytest.raises(InputError, match="raw size 6×8"):
        apply_raw_steps(steps, np.zeros((5, 8)))


def test_raw_record_round_trips_through_hdf5(tmp_path):
    dark = np.arange(12.0).reshape(3, 4)
    for steps in (RawSteps((3, 4), 2.5, None, (0, 2, 1, 3), 1, (1, -1)), RawSteps((3, 4), 0.0, dark, None, 2)):
        with h5py.File(tmp_path / "r.h5", "w") as f:
            write_record(f, steps)
        with h5py.File(tmp_path / "r.h5", "r") as f:
            back = read_record(f, "r.h5")
        assert (back.shape, back.dark_level, back.crop, back.bin, back.shift) == \
               (steps.shape, steps.dark_level, steps.crop, steps.bin, steps.shift)
        np.testing.assert_array_equal(back.dark_frame, steps.dark_frame)


# ---- calibrate psf ------------------------------------------------------------------------------------
def point_frames(tmp_path, n=2):
    """n 20×24 frames: dark level 5, a 2×2 spot of 105 (100 above the dark) with its top-left at (4, 6)."""
    frame = np.full((20, 24), 5.0)
    frame[4:6, 6:8] = 105.0
    return [save(tmp_path / f"psf{i}.npy", frame) for i in range(n)]


def test_psf_centring_report_and_center(tmp_path):
    frames = point_frames(tmp_path)
    result = calibrate_psf(frames, ["5"], None, None, 1, center=False)
    assert result.peak == (4, 6) and result.centroid == pytest.approx((4.5, 6.5))
    assert np.linalg.norm(result.psf) == pytest.approx(1.0)
    np.testing.assert_allclose(result.psf[4:6, 6:8], 0.5)      # four equal pixels of a unit-norm PSF
    centred = calibrate_psf(frames, ["5"], None, None, 1, center=True)
    assert centred.steps.shift == (6, 6)                      # round((10, 12) − (4.5, 6.5)) = (6, 6) (half to even)
    assert tuple(centroid_of(centred.psf)) == pytest.approx((10.5, 12.5))


def test_psf_bin_and_crop(tmp_path):
    result = calibrate_psf(point_frames(tmp_path), None, 2, (2, 18, 4, 24), 2)   # corner patch [1:3, 1:3]: 5
    assert result.psf.shape == (8, 10) and result.steps.dark_level == 5.0
    assert np.flatnonzero(result.psf.ravel()).tolist() == [1 * 10 + 1]           # the spot fills one 2×2 bin


def test_calibrate_psf_cli_writes_a_one_band_calibration_that_takes_raw_frames(tmp_path, capsys):
    frames = point_frames(tmp_path)
    code = main(["calibrate", "psf", *frames, "--dark", "5", "--bin", "2", "--center", "--wavelength", "600",
                 "-o", str(tmp_path / "cal.h5"), "--png", str(tmp_path / "pic")])
    assert code == 0
    out = capsys.readouterr().out
    assert "centroid at (2.0, 3.0), frame centre (5, 6)" in out and "moved by (+3, +3)" in out and "support" in out
    assert (tmp_path / "pic_psf.png").exists() and (tmp_path / "pic_autocorrelation.png").exists()
    cal = Calibration.load(tmp_path / "cal.h5")
    assert cal.filters.shape == (1, 10, 12) and cal.filters.min() == 1 and cal.wavelengths.tolist() == [600.0]
    assert cal.raw.shape == (20, 24) and cal.raw.bin == 2 and cal.raw.shift == (3, 3) and cal.raw.dark_level == 5
    raw = np.full((20, 24), 5.0)
    raw[10, 12] = 45.0                                         # → 10 in bin (5, 6), shifted to (8, 9)
    prepared, b = prepare(raw, tmp_path / "cal.h5")
    assert b.shape == (10, 12) and b[8, 9] == 10.0 and b.sum() == 10.0
    assert "raw steps applied to the measurement" in prepared.source
    ramp = np.arange(120.0).reshape(10, 12)                    # (a constant frame is refused: nothing to solve)
    assert prepare(ramp, tmp_path / "cal.h5")[1].sum() == ramp.sum()     # calibration-size frames as they are


def test_all_dark_psf_is_refused(tmp_path, capsys):
    frame = save(tmp_path / "dark.npy", np.full((8, 8), 3.0))
    assert main(["calibrate", "psf", frame, "--dark", "3", "-o", str(tmp_path / "cal.h5")]) == 2
    err = capsys.readouterr().err
    assert "nothing above the dark level" in err and err.count("\n") == 1 and not (tmp_path / "cal.h5").exists()


# ---- calibration files: the raw record and the defect map ------------------------------------------------
def test_dead_pixels_of_a_calibration_are_left_out_after_a_crop(tmp_path):
    dead = np.zeros((6, 7), bool)
    dead[2, 3] = True
    cal = Calibration(np.ones((6, 7)), np.ones((2, 6, 7)), [500, 600], dead_pixels=dead)
    cal.save(tmp_path / "cal.h5")
    loaded = Calibration.load(tmp_path / "cal.h5")
    np.testing.assert_array_equal(loaded.dead_pixels, dead)
    out, b = preprocess(loaded, np.ones((6, 7)), Preprocessing(crop=(1, 5, 1, 6)))
    assert out.dead_pixels is None and b[1, 2] == 0 and out.filters[:, 1, 2].tolist() == [0, 0] and b.sum() == 19


# ---- a measurement's own steps: frames averaged, dark, bin (prepare and reconstruct) --------------------------
def test_measurement_frames_are_averaged_darkened_and_binned(tmp_path):
    cal = Calibration(np.ones((2, 3)), np.ones((1, 2, 3)), [550.0])
    frames = [save(tmp_path / f"m{i}.npy", np.arange(24.0).reshape(4, 6) + 2 * i) for i in range(2)]
    dark = save(tmp_path / "d.npy", np.full((4, 6), 4.0))
    options = Preprocessing(dark=(dark,), bin=2, normalize_psf=False, normalize_filters=False)
    lines = []
    prepared, b = prepare(frames, cal, options, report=lines.append)
    # mean = arange + 1; − 4, clipped: rows [0 0 0 0 1 2] [3 … 8] [9 … 14] [15 … 20]; 2×2 means
    np.testing.assert_array_equal(b, [[(3 + 4) / 4, (5 + 6) / 4, (1 + 2 + 7 + 8) / 4],
                                      [(9 + 10 + 15 + 16) / 4, (11 + 12 + 17 + 18) / 4, (13 + 14 + 19 + 20) / 4]])
    assert lines == ["measurement: mean of 2 frames", "steps applied to the measurement: raw 4×6: dark mean dark "
                     "frame, crop none, bin 2×2, shift (0, 0)"] and prepared.source.endswith(lines[1])
    level = Preprocessing(dark=3.0, normalize_psf=False, normalize_filters=False)
    np.testing.assert_array_equal(prepare(np.array([[1.0, 5, 4], [10, 3, 2]]), cal, level)[1], [[0, 2, 1], [7, 0, 0]])


def test_a_raw_size_measurement_takes_its_own_dark_and_the_recorded_bin():
    cal = Calibration(np.ones((2, 3)), np.ones((1, 2, 3)), [550.0], raw=RawSteps((4, 6), dark_level=100.0, bin=2))
    frame = np.arange(24.0).reshape(4, 6)
    plain = Preprocessing(normalize_psf=False, normalize_filters=False)
    np.testing.assert_array_equal(prepare(frame + 100, cal, plain)[1], bin_pixels(frame, 2))
    own = replace(plain, dark=1.0, bin=2)                       # its own dark 1 replaces the recorded 100
    prepared, b = prepare(frame, cal, own)
    np.testing.assert_array_equal(b, bin_pixels(np.maximum(frame - 1, 0), 2))
    assert "raw steps applied to the measurement, its own dark: raw 4×6: dark 1," in prepared.source
    with pytest.raises(InputError, match="whose recorded steps bin it 2×2; leave out --bin"):
        prepare(frame, cal, replace(plain, bin=3))


@pytest.fixture
def small_camera(tmp_path):
    """A one-band 8×10 calibration whose PSF frames were raw 16×20, dark 100, binned 2×2."""
    psf = np.random.default_rng(0).random((8, 10))
    path = tmp_path / "cal.h5"
    Calibration(psf, np.ones((1, 8, 10)), [550.0], raw=RawSteps((16, 20), 100.0, bin=2)).save(path)
    return str(path)


def test_reconstruct_reports_and_records_the_measurement_steps(small_camera, tmp_path, capsys):
    ramp = np.arange(17 * 21.0).reshape(17, 21)             # (a constant frame is refused: nothing to solve)
    frames = [save(tmp_path / f"m{i}.npy", ramp + v) for i, v in enumerate((7.0, 9.0, 1e6))]
    dark = save(tmp_path / "dark.npy", np.full((17, 21), 3.0))
    assert main(["reconstruct", *frames, "--average", "2", "--dark", dark, "--bin", "2", "--calibration",
                 small_camera, "-o", str(tmp_path / "cube.h5"), "--iters", "5", "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "measurement: mean of 2 frames\nsteps applied to the measurement: raw 17×21: dark mean dark frame, " \
           "crop none, bin 2×2" in out
    with h5py.File(tmp_path / "cube.h5", "r") as f:
        attrs = dict(f.attrs)
    assert json.loads(attrs["measurement_path"]) == frames[:2] and attrs["dark_path"] == dark
    assert json.loads(attrs["preprocessing"])["bin"] == 2 and json.loads(attrs["preprocessing"])["dark"] == [dark]
    assert "mean of 2 frames; steps applied to the measurement" in attrs["calibration"]


@pytest.mark.parametrize("shapes, extra, message", [
    ([(16, 20)] * 2, ["--average", "3"], "--average 3: only 2 measurement files given"),
    ([(16, 20), (16, 22)], [], "(frames of mixed sizes)"),
    ([(17, 21)], ["--dark", "DARK"], "16×20, but the frames are 17×21"),
    ([(16, 20)], ["--bin", "4"], "recorded steps bin it 2×2; leave out --bin"),
    ([(17, 21)], ["--bin", "40"], "--bin 40: larger than the 17×21 frame"),
])
def test_bad_measurement_steps_exit_2_with_one_line_and_write_nothing(small_camera, tmp_path, capsys, shapes, extra,
                                                                      message):
    frames = [save(tmp_path / f"m{i}.npy", np.ones(shape)) for i, shape in enumerate(shapes)]
    dark = save(tmp_path / "dark.npy", np.zeros((16, 20)))
    output = tmp_path / "out" / "cube.h5"
    code = main(["reconstruct", *frames, *[dark if a == "DARK" else a for a in extra], "--calibration", small_camera,
                 "-o", str(output), "--png", str(tmp_path / "out" / "p"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


# ---- calibrate filters, step by step ---------------------------------------------------------------------
def test_wavelength_grid_includes_stop_and_counts_frames(tmp_path):
    sweep = open_sweep(save(tmp_path / "s.npy", np.ones((6, 2, 2), np.uint16)))
    np.testing.assert_allclose(sweep_wavelengths("370:380:2", sweep), [370, 372, 374, 376, 378, 380])
    assert sweep.code_max == 65535
    with pytest.raises(InputError, match="6 frames but 5 wavelengths"):
        sweep_wavelengths("370:378:2", sweep)


def test_power_is_interpolated_normalised_and_must_cover_the_sweep(tmp_path):
    csv = tmp_path / "power.csv"
    csv.write_text("Cornerstone Wavelength  (nm),uW output\n400,2\n440,4\n480,2\n")
    np.testing.assert_allclose(power_weights(csv, np.arange(400.0, 481, 20)), [0.5, 0.75, 1.0, 0.75, 0.5])
    with pytest.raises(InputError, match="covers 400–480 nm, the sweep needs 390–480 nm"):
        power_weights(csv, np.array([390.0, 480.0]))


def test_band_integration_is_the_trapezoid_rule_with_interpolated_ends():
    lam = np.array([400.0, 410, 420, 430])
    values = np.array([0.0, 1, 0, 1])[:, None]              # one pixel
    edges = np.array([405.0, 415, 430])
    # band 1: (405, .5) (410, 1) (415, .5): 5·.75 + 5·.75 = 7.5; band 2: (415, .5) (420, 0) (430, 1): 1.25 + 5 = 6.25
    np.testing.assert_allclose(integrate_bands(lam, values, edges)[:, 0], [7.5, 6.25])
    linear = integrate_bands(lam, lam[:, None], equal_edges(3, 401.0, 428.0))[:, 0]
    np.testing.assert_allclose(linear, [(410 ** 2 - 401 ** 2) / 2, (419 ** 2 - 410 ** 2) / 2, (428 ** 2 - 419 ** 2) / 2])
    np.testing.assert_allclose(band_centres(equal_edges(4, 386, 898)), [450, 578, 706, 834])
    with pytest.raises(InputError, match="do not lie inside the sweep"):
        integrate_bands(lam, values, np.array([395.0, 420]))


def defect_sweep(tmp_path):
    """5 frames 6×8 (uint16, dark 10), 400–480 nm: pixel (y, x) sees 1000 counts at frame x mod 5; (1, 1) dead,
    (2, 3) hot (1000 in every frame), (4, 5) saturated in frame 2."""
    frames = np.full((5, 6, 8), 10, np.uint16)
    for x in range(8):
        frames[x % 5, :, x] += 1000
    frames[:, 1, 1] = 10
    frames[:, 2, 3] = 1010
    frames[2, 4, 5] = 65535
    folder = tmp_path / "sweep"
    folder.mkdir()
    for i, frame in enumerate(frames):
        tifffile.imwrite(folder / f"f{i}.tif", frame)
    return frames, folder


def test_filters_defect_map_power_and_bands(tmp_path, capsys):
    frames, folder = defect_sweep(tmp_path)
    (tmp_path / "power.csv").write_text("400,1\n480,1\n")
    (tmp_path / "edges.csv").write_text("edge (nm)\n400\n440\n480\n")
    assert main(["calibrate", "filters", str(folder), "--wavelengths", "400:480:20", "--power",
                 str(tmp_path / "power.csv"), "--dark", "10", "--exposure", "2", "--band-edges",
                 str(tmp_path / "edges.csv"), "-o", str(tmp_path / "f.h5"), "--png", str(tmp_path / "f")]) == 0
    assert "1 dead, 1 hot, 1 saturated" in capsys.readouterr().out
    with h5py.File(tmp_path / "f.h5", "r") as f:
        dead, filters, wavelengths = f["dead_pixels"][...], f["filters"][...], f["wavelength"][...]
        assert "psf" not in f
    expected = np.zeros((6, 8), bool)
    expected[1, 1] = expected[2, 3] = expected[4, 5] = True
    np.testing.assert_array_equal(dead, expected)
    np.testing.assert_allclose(wavelengths, [420, 460])
    # t = 1000 / exposure 2 = 500 at one wavelength, 0 elsewhere (power flat); bands 400–440–480 nm:
    # at 420 nm (x = 1): 20·500/2 + 20·500/2 = 10000 in band 1 (the largest integral); at 400 nm (x = 0):
    # 20·500/2 = 5000 in band 1; at 440 nm (x = 2), on the edge: 5000 in each band
    np.testing.assert_allclose(filters[:, 0, :3], [[0.5, 1, 0.5], [0, 0, 0.5]])
    assert filters[:, 2, 3].tolist() == [0, 0] and (tmp_path / "f_peak_wavelength.png").exists()


def test_a_pixel_bright_in_the_dark_frame_is_hot():
    transmission = np.zeros((3, 2, 4))
    transmission[np.arange(8) % 3, np.arange(8) // 4, np.arange(8) % 4] = 1.0    # each pixel peaks once
    dark = np.zeros((2, 4))
    dark[1, 2] = 0.2                     # > 10 % of the median peak signal (1) above the dark's median
    defects = find_defects(transmission, transmission.max(axis=0), np.zeros((2, 4), bool),
                           RawSteps((2, 4), dark_frame=dark))
    assert np.argwhere(defects.hot).tolist() == [[1, 2]] and not defects.dead.any()


def test_stacks_read_like_folders(tmp_path):
    frames, folder = defect_sweep(tmp_path)
    np.save(tmp_path / "s.npy", frames)
    tifffile.imwrite(tmp_path / "s.tif", frames)
    with h5py.File(tmp_path / "s.h5", "w") as f:
        f["frames"] = frames
    for source in (folder, tmp_path / "s.npy", tmp_path / "s.tif", tmp_path / "s.h5"):
        sweep = open_sweep(source)
        assert len(sweep) == 5 and sweep.shape == (6, 8) and sweep.code_max == 65535
        np.testing.assert_array_equal(sweep.frame(2), frames[2])


# ---- bad sweeps: exit 2, one line, nothing written -----------------------------------------------------------
def bad_sweep(tmp_path, case):
    """(sweep, extra options) for each kind of bad input."""
    frames, folder = defect_sweep(tmp_path)
    if case == "mixed sizes":
        tifffile.imwrite(folder / "f9.tif", np.zeros((5, 8), np.uint16))
    elif case == "unreadable":
        (folder / "f3.tif").write_bytes(b"not a tiff")
    elif case == "all dark":
        np.save(tmp_path / "dark.npy", np.full((5, 6, 8), 10, np.uint16))
        return tmp_path / "dark.npy", []
    elif case == "power":
        (tmp_path / "power.csv").write_text("wavelength,power\n420,1\n480,2\n")
        return folder, ["--power", str(tmp_path / "power.csv")]
    return folder, []


@pytest.mark.parametrize("case, wavelengths, message", [
    ("missing wavelengths", "400:460:20", "5 frames but 4 wavelengths"),
    ("mixed sizes", "400:500:20", "frames of mixed sizes"),
    ("power", "400:480:20", "covers 420–480 nm, the sweep needs 400–480 nm"),
    ("all dark", "400:480:20", "nothing above the dark level"),
    ("unreadable", "400:480:20", "not a readable image"),
])
def test_a_bad_sweep_exits_2_with_one_line_and_writes_nothing(tmp_path, capsys, case, wavelengths, message):
    sweep, extra = bad_sweep(tmp_path, case)
    output = tmp_path / "out" / "cal.h5"
    code = main(["calibrate", "filters", str(sweep), "--wavelengths", wavelengths, "--dark", "10", "--bands", "2",
                 "--range", "400:480", "-o", str(output), "--png", str(tmp_path / "out" / "p"), *extra])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "out").exists()


# ---- the loop: simulated sweep → calibrate filters → reconstruct ------------------------------------------------
@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    out = tmp_path_factory.mktemp("lab")
    assert main(["simulate", str(out), "--sweep", "--size", "48x64", "--bands", "16"]) == 0
    return out


def test_simulated_sweep_recovers_the_filters_and_the_reconstruction(lab, tmp_path):
    from clsdcam.io import read_cube
    from clsdcam.metrics import psnr
    from clsdcam.solve.solver import reconstruct

    darks = sorted(str(p) for p in (lab / "dark").glob("*.tif"))
    assert main(["calibrate", "filters", str(lab / "sweep"), "--wavelengths", str(lab / "sweep_wavelengths.csv"),
                 "--power", str(lab / "power.csv"), "--dark", *darks, "--bands", "16", "--range", "386:898",
                 "--psf", str(lab / "psf_calibration.h5"), "-o", str(tmp_path / "recovered.h5")]) == 0
    recovered = Calibration.load(tmp_path / "recovered.h5")
    with h5py.File(lab / "true_filters.h5", "r") as f:         # the truth at the sweep's resolution, same bands
        true = integrate_bands(f["wavelength"][...], f["filters"][...], equal_edges(16, 386, 898))
    true /= true.max()
    assert np.linalg.norm(recovered.filters - true) / np.linalg.norm(true) < 0.02
    assert not recovered.dead_pixels.any()
    truth = read_cube(lab / "truth.h5")["cube"]
    with_true, with_recovered = (psnr(reconstruct(lab / "measurement.npy", cal, iters=200).cube, truth)
                                 for cal in (lab / "calibration.h5", tmp_path / "recovered.h5"))
    assert with_recovered > with_true - 0.3
