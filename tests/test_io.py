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
