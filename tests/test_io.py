"""Measurement loaders, cube files and atomic writes."""
import h5py
import numpy as np
import pytest
import tifffile
from PIL import Image

from clsdcam.errors import InputError
from clsdcam.io import atomic_output, load_measurement, read_cube, save_measurement, write_cube

FRAME16 = (np.arange(35).reshape(5, 7) * 1000).astype(np.uint16)


@pytest.mark.parametrize("name, write", [
    ("m.png", lambda p, a: Image.fromarray(a).save(p)),
    ("m.tif", lambda p, a: tifffile.imwrite(p, a)),
    ("m.npy", lambda p, a: np.save(p, a)),
    ("m.h5", lambda p, a: h5py.File(p, "w").create_dataset("measurement", data=a).file.close()),
])
@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_measurement_formats_keep_raw_values(tmp_path, name, write, dtype):
    frame = (FRAME16 if dtype == np.uint16 else FRAME16 // 200).astype(dtype)
    write(tmp_path / name, frame)
    loaded = load_measurement(tmp_path / name)
    assert loaded.dtype == np.float64
    np.testing.assert_array_equal(loaded, frame)


def test_colour_image_and_3d_arrays_are_rejected(tmp_path):
    Image.fromarray(np.zeros((4, 5, 3), np.uint8)).save(tmp_path / "rgb.png")
    with pytest.raises(InputError, match="2-D grey"):
        load_measurement(tmp_path / "rgb.png")


def test_non_finite_values_are_counted_and_located(tmp_path):
    frame = np.ones((4, 6))
    frame[2, 3] = np.nan
    frame[3, 0] = np.inf
    np.save(tmp_path / "bad.npy", frame)
    with pytest.raises(InputError, match=r"bad.npy: 2 non-finite values \(NaN/Inf\), first at \(2, 3\)"):
        load_measurement(tmp_path / "bad.npy")


@pytest.mark.parametrize("name, content, message", [
    ("e.npy", b"", "empty file"),
    ("t.npy", b"\x93NUMPY\x01\x00v\x00{'descr'", "not a readable .npy"),
    ("t.png", b"\x89PNG\r\n\x1a\n\x00\x00", "not a readable image"),
    ("t.h5", b"\x89HDF\r\n\x1a\n", "not a readable HDF5"),
    ("m.jpg", b"abc", "unknown format"),
])
def test_broken_files_give_one_line_errors(tmp_path, name, content, message):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(InputError, match=message) as info:
        load_measurement(tmp_path / name)
    assert name in str(info.value) and "\n" not in str(info.value)


def test_object_arrays_and_wrong_keys(tmp_path):
    np.save(tmp_path / "s.npy", np.array(["a", "b"]))
    with pytest.raises(InputError, match="expected real numbers"):
        load_measurement(tmp_path / "s.npy")
    with h5py.File(tmp_path / "k.h5", "w") as f:
        f["frame"] = np.ones((2, 2))
    with pytest.raises(InputError, match="no dataset 'measurement' \\(found: frame\\)"):
        load_measurement(tmp_path / "k.h5")


def test_cube_round_trip_with_history_and_attributes(tmp_path):
    cube = np.random.default_rng(0).random((3, 4, 5)).astype(np.float32)
    history = [{"iteration": i, "objective": 1.0 / i} for i in (1, 2)]
    write_cube(tmp_path / "c.h5", cube, [1.0, 2.0, 3.0], history, {"iters": 2, "device": None, "shape": (4, 5)})
    back = read_cube(tmp_path / "c.h5")
    np.testing.assert_array_equal(back["cube"], cube)
    assert back["history"]["objective"].tolist() == [1.0, 0.5] and back["attrs"]["iters"] == 2
    assert back["attrs"]["shape"].tolist() == [4, 5] and back["attrs"]["device"] == ""


def test_atomic_output_keeps_the_old_file_on_failure(tmp_path):
    target = tmp_path / "out.h5"
    target.write_text("old")
    with pytest.raises(RuntimeError):
        with atomic_output(target) as tmp:
            tmp.write_text("half")
            raise RuntimeError("killed")
    assert target.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["out.h5"]
    with atomic_output(target) as tmp:
        tmp.write_text("new")
    assert target.read_text() == "new" and sorted(p.name for p in tmp_path.iterdir()) == ["out.h5"]


def test_save_measurement_round_trip(tmp_path):
    frame = np.random.default_rng(1).random((6, 7))
    for name in ("a.npy", "a.h5"):
        np.testing.assert_allclose(load_measurement(save_measurement(tmp_path / name, frame)), frame, rtol=1e-7)


# ---- one name for the wavelengths ---------------------------------------------------------------
WAVELENGTHS = np.array([450.0, 550.0, 650.0])
CUBE = np.random.default_rng(2).random((3, 4, 5)).astype(np.float32)


def written_files(folder) -> dict:
    """{what: path} of each kind of file clsdcam writes with band wavelengths (``sweep``: the sweep's true filters)."""
    from clsdcam.batch import parts
    from clsdcam.camera.calibration import Calibration
    from clsdcam.sim.camera import write_truth
    from clsdcam.sim.sweep import sweep_of, write_sweep
    from clsdcam.sim.video import write_video
    from clsdcam.sim import simulate

    calibration = Calibration(np.ones((4, 5)), np.ones((3, 4, 5)), WAVELENGTHS)
    write_cube(folder / "cube.h5", CUBE, WAVELENGTHS)
    write_truth(folder / "truth.h5", CUBE, WAVELENGTHS)
    video = write_video(folder / "video", calibration, np.ones((2, 4, 5), np.float32), np.stack([CUBE, CUBE]))
    with h5py.File(folder / "part.h5", "w") as f:
        parts.write_cube(f, 0, 1, CUBE, WAVELENGTHS)
    sweep = write_sweep(folder / "sweep", simulate("leds", (16, 16), 2), sweep_of(WAVELENGTHS, np.ones((3, 16, 16))))
    return {"cube": folder / "cube.h5", "truth": folder / "truth.h5", "calibration": video["calibration"],
            "video truth": video["truth"], "batch part": folder / "part.h5", "sweep": sweep["true_filters"]}


def test_every_file_names_its_wavelengths_wavelength_in_nm(tmp_path):
    for what, path in written_files(tmp_path).items():
        with h5py.File(path, "r") as f:
            assert "wavelength" in f and "wavelengths" not in f, what
            np.testing.assert_array_equal(f["wavelength"][...], WAVELENGTHS, err_msg=what)
            assert f["wavelength"].attrs["units"] == "nm", what


def test_files_with_the_old_name_still_read(tmp_path):
    """Calibrations, truths (one cube, a video) and batch parts written before the one name, with ``wavelengths``."""
    from clsdcam.batch import parts
    from clsdcam.camera.calibration import Calibration
    from clsdcam.export import read_source

    with h5py.File(tmp_path / "calibration.h5", "w") as f:
        f["psf"], f["filters"], f["wavelengths"] = np.ones((4, 5)), np.ones((3, 4, 5)), WAVELENGTHS
    with h5py.File(tmp_path / "truth.h5", "w") as f:
        f["cube"], f["wavelengths"] = CUBE, WAVELENGTHS
    with h5py.File(tmp_path / "video.h5", "w") as f:
        f["cubes"], f["wavelengths"] = np.stack([CUBE, CUBE]), WAVELENGTHS
    folder = parts.parts_dir(tmp_path / "out.h5")
    folder.mkdir()
    (folder / "batch.json").write_text('{"fingerprint": "old"}')
    with h5py.File(parts.part_path(folder, 0, 1), "w") as f:
        f["cubes"], f["wavelengths"] = CUBE[None], WAVELENGTHS
        parts.write_columns(f, {"index": [0], "iterations": [5], "seconds": [1.0], "warm": [False],
                                "stop_reason": ["budget"], "error": [""]})
    parts.assemble(tmp_path / "out.h5", 1, {}, {})
    np.testing.assert_array_equal(Calibration.load(tmp_path / "calibration.h5").wavelengths, WAVELENGTHS)
    for path in ("truth.h5", "video.h5", "out.h5"):
        np.testing.assert_array_equal(read_source(tmp_path / path)["wavelengths"], WAVELENGTHS, err_msg=path)
