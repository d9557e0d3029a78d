"""The napari reader without napari or a display: ``napari cube.h5`` goes through npe2 (the ``napari.manifest``
entry point, clsdcam/napari.yaml) to clsdcam.napari_reader, which returns napari's layer data tuples."""
import subprocess
import sys

import h5py
import npe2
import numpy as np
import pytest

from clsdcam.cli import main
from clsdcam.io import write_cube
from clsdcam.napari_reader import napari_get_reader


def read_as_napari_does(path) -> list[tuple]:
    """The layers napari would add for ``path`` with the clsdcam plugin chosen (npe2 finds it as napari does)."""
    npe2.PluginManager.instance().discover()
    return npe2.read([str(path)], stack=False, plugin_name="clsdcam")


def test_a_cube_opens_with_its_wavelengths_axes_and_name(tmp_path):
    cube = np.random.default_rng(0).random((5, 6, 7), dtype=np.float32)
    wavelengths = np.array([400.0, 450.0, 520.0, 610.0, 890.0])
    path = write_cube(tmp_path / "leaf.h5", cube, wavelengths, attrs={"tv_chosen": 3e-4})
    (data, kwargs, kind), = read_as_napari_does(path)
    assert kind == "image" and isinstance(data, np.ndarray) and np.array_equal(data, cube)
    assert kwargs["name"] == "leaf" and kwargs["axis_labels"] == ("λ", "y", "x")
    assert np.array_equal(kwargs["metadata"]["wavelengths"], wavelengths)
    assert kwargs["metadata"]["wavelength_unit"] == "nm" and kwargs["metadata"]["attrs"]["tv_chosen"] == 3e-4
    assert kwargs["contrast_limits"] == (0.0, pytest.approx(np.percentile(cube, 99.9)))
    assert kwargs["colormap"] == "magma"


def test_a_batch_output_and_a_video_truth_open_frame_by_frame(tmp_path):
    video = tmp_path / "v"
    assert main(["simulate", str(video), "--frames", "3", "--size", "16x20", "--bands", "4", "--scene", "leds"]) == 0
    assert main(["batch", str(video / "frames.npy"), "--calibration", str(video / "calibration.h5"),
                 "-o", str(tmp_path / "cubes.h5"), "--workers", "0", "--iters", "3", "--cold-iters", "3",
                 "--quiet"]) == 0
    with h5py.File(video / "truth.h5", "r") as f:
        truth, wavelengths = f["cubes"][...], f["wavelength"][...]
    with h5py.File(tmp_path / "cubes.h5", "r") as f:
        cubes = f["cubes"][...]
    for path, expected in ((tmp_path / "cubes.h5", cubes), (video / "truth.h5", truth)):
        (data, kwargs, _), = read_as_napari_does(path)
        assert not isinstance(data, np.ndarray), "the frames should stay on disk (a dask array)"
        assert data.shape == (3, 4, 16, 20) and np.array_equal(np.asarray(data), expected)
        assert kwargs["axis_labels"] == ("frame", "λ", "y", "x") and kwargs["name"] == path.stem
        assert np.array_equal(kwargs["metadata"]["wavelengths"], wavelengths)
        assert 0 < kwargs["contrast_limits"][1] <= np.nanmax(expected[0])


def test_files_that_are_not_cubes_are_left_to_other_readers(tmp_path):
    assert main(["simulate", str(tmp_path), "--size", "16x20", "--bands", "2", "--scene", "leds"]) == 0
    (tmp_path / "broken.h5").write_bytes(b"not HDF5")
    with h5py.File(tmp_path / "flat.h5", "w") as f:
        f["cube"] = np.zeros((4, 5))      # a "cube" that is not (K, H, W)
    for name in ("calibration.h5", "measurement.npy", "broken.h5", "flat.h5", "missing.h5"):
        assert napari_get_reader(str(tmp_path / name)) is None, name
    assert napari_get_reader(str(tmp_path / "truth.h5")) is not None
    assert napari_get_reader([str(tmp_path / "truth.h5"), str(tmp_path / "calibration.h5")]) is None


def test_an_empty_frame_gets_usable_contrast_limits(tmp_path):
    path = write_cube(tmp_path / "dark.h5", np.zeros((2, 3, 4)), [500.0, 600.0])
    (_, kwargs, _), = read_as_napari_does(path)
    assert kwargs["contrast_limits"] == (0.0, 1.0)


def test_the_installed_manifest_is_valid_and_its_reader_imports():
    manifest = npe2.PluginManifest.from_distribution("clsdcam")     # through the napari.manifest entry point
    manifest.validate_imports()
    (reader,) = manifest.contributions.readers
    assert reader.command == "clsdcam.get_reader" and "*.h5" in reader.filename_patterns


def test_npe2_validate_passes(tmp_path):
    """The command the acceptance names, from a folder with no ``clsdcam`` in it (npe2 tries the name as a path
    first)."""
    done = subprocess.run([sys.executable, "-m", "npe2", "validate", "clsdcam", "--imports"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and "valid" in done.stdout, done.stdout + done.stderr
