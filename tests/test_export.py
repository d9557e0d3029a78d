"""Exports (ENVI, TIFF, NetCDF, PNG, self-contained batch copies) read back with the libraries other tools use;
``clsdcam export`` and ``clsdcam show`` end to end; a batch output whose parts are gone is refused."""
import shutil

import h5py
import numpy as np
import pytest

from clsdcam.cli import main
from clsdcam.cli.export import FORMATS as CLI_FORMATS
from clsdcam.errors import InputError
from clsdcam.export import FORMATS, check_virtual_sources, export
from clsdcam.io import read_wavelengths, write_cube

WAVELENGTHS = np.array([412.5, 487.25, 551.0, 630.125, 702.0])


@pytest.fixture
def cube_file(tmp_path):
    cube = np.random.default_rng(0).random((5, 6, 7), dtype=np.float32)
    attrs = {"backend": "numpy", "iterations": np.int64(3), "skip": np.True_, "field_shape": (12, 14), "tv": None}
    history = [{"iteration": i + 1, "data": 1.0 / (i + 1), "objective": 2.0 / (i + 1), "seconds": 0.1 * i}
               for i in range(4)]
    return write_cube(tmp_path / "cube.h5", cube, WAVELENGTHS, history, attrs), cube


@pytest.fixture(scope="module")
def batch_output(tmp_path_factory):
    """A batch output of 3 frames: OUT.h5 with a virtual ``cubes`` over OUT.h5.parts/."""
    folder = tmp_path_factory.mktemp("batch")
    assert main(["simulate", str(folder), "--size", "24x32", "--bands", "4", "--frames", "3", "--scene", "leds"]) == 0
    output = folder / "out.h5"
    assert main(["batch", str(folder / "frames.npy"), "--calibration", str(folder / "calibration.h5"),
                 "-o", str(output), "--workers", "0", "--iters", "3", "--chunk", "1", "--quiet"]) == 0
    return output


def moved(batch_output, tmp_path):
    """A copy of the batch output's folder (output and parts), to break without harming the module's one."""
    shutil.copytree(batch_output.parent, tmp_path / "copy")
    return tmp_path / "copy" / batch_output.name


def assert_one_line_error(capsys, *words):
    err = capsys.readouterr().err.strip()
    assert err.startswith("clsdcam: error:") and "\n" not in err and "Traceback" not in err
    assert all(word in err for word in words), err


def nothing_written(folder, name):
    return not any(p.name.startswith((name, f".{name}")) for p in folder.iterdir())


# ---- each format read back ------------------------------------------------------------------------------
def test_envi_reads_back_with_spectral_python(cube_file, tmp_path):
    from spectral import envi

    path, cube = cube_file
    assert export(path, tmp_path / "out.img", "envi") == [tmp_path / "out.hdr", tmp_path / "out.img"]
    image = envi.open(str(tmp_path / "out.hdr"))
    assert image.metadata["interleave"] == "bsq" and image.metadata["data type"] == "4"   # 4: float32
    np.testing.assert_array_equal(image.open_memmap(interleave="bsq"), cube)
    np.testing.assert_array_equal(image.bands.centers, WAVELENGTHS)
    assert image.bands.band_unit == "nm"


def test_tiff_has_one_page_per_band_and_its_wavelengths(cube_file, tmp_path):
    import tifffile

    path, cube = cube_file
    export(path, tmp_path / "out.tif", "tiff")
    with tifffile.TiffFile(tmp_path / "out.tif") as tif:
        assert len(tif.pages) == 5 and tif.pages[0].shape == (6, 7) and tif.pages[0].dtype == np.float32
        np.testing.assert_array_equal(tif.asarray(), cube)
        metadata = tif.shaped_metadata[0]
    np.testing.assert_array_equal(metadata["wavelength"], WAVELENGTHS)
    assert metadata["wavelength_units"] == "nm"


def test_netcdf_reads_back_with_xarray(cube_file, tmp_path):
    import xarray

    path, cube = cube_file
    export(path, tmp_path / "out.nc", "netcdf")
    with xarray.open_dataset(tmp_path / "out.nc", engine="h5netcdf") as ds:
        assert ds["cube"].dims == ("wavelength", "y", "x") and ds["cube"].dtype == np.float32
        np.testing.assert_array_equal(ds["cube"].values, cube)
        np.testing.assert_array_equal(ds["wavelength"].values, WAVELENGTHS)
        assert ds["wavelength"].attrs["units"] == "nm"
        assert ds.attrs["backend"] == "numpy" and ds.attrs["iterations"] == 3 and ds.attrs["skip"] == 1
        np.testing.assert_array_equal(ds.attrs["field_shape"], [12, 14])


def test_cube_files_open_in_xarray_as_they_are(cube_file):
    import xarray

    path, cube = cube_file
    with xarray.open_dataset(path, engine="h5netcdf") as ds:
        assert ds["cube"].dims == ("wavelength", "y", "x")
        np.testing.assert_array_equal(ds["cube"].values, cube)
        np.testing.assert_array_equal(ds["wavelength"].values, WAVELENGTHS)
        assert ds["wavelength"].attrs["units"] == "nm"


@pytest.mark.parametrize("bands", [5, 1])
def test_png_is_the_false_colour_image_or_grey_for_one_band(tmp_path, bands):
    from PIL import Image

    cube = np.random.default_rng(1).random((bands, 6, 7), dtype=np.float32)
    path = write_cube(tmp_path / "cube.h5", cube, WAVELENGTHS[:bands])
    export(path, tmp_path / "out.png", "png")
    with Image.open(tmp_path / "out.png") as image:
        assert image.size == (7, 6) and image.mode == ("RGB" if bands > 1 else "L")


def test_the_formats_agree_with_the_command_line():
    assert CLI_FORMATS == FORMATS


# ---- batch outputs ------------------------------------------------------------------------------------
def test_the_self_contained_copy_reads_the_same_frames_without_the_parts(batch_output, tmp_path, capsys):
    output = moved(batch_output, tmp_path)
    copy = tmp_path / "all.h5"
    assert main(["export", str(output), "-o", str(copy)]) == 0
    assert str(copy) in capsys.readouterr().out
    with h5py.File(output, "r") as f:
        frames, records, attrs = f["cubes"][...], {k: f[k][...] for k in f if k != "cubes"}, dict(f.attrs)
        scales = [[s.name for s in dim.values()] for dim in f["cubes"].dims]
    shutil.rmtree(output.with_name("out.h5.parts"))
    with h5py.File(copy, "r") as f:
        assert not f["cubes"].is_virtual and f["cubes"].chunks == (1,) + frames.shape[1:]
        np.testing.assert_array_equal(f["cubes"][...], frames)
        assert np.isfinite(frames).all() and set(f) - {"cubes"} == set(records)
        for key, values in records.items():
            np.testing.assert_array_equal(f[key][...], values)
        assert sorted(f.attrs) == sorted(attrs) and f.attrs["fingerprint"] == attrs["fingerprint"]
        assert [[s.name for s in dim.values()] for dim in f["cubes"].dims] == scales


def test_the_self_contained_copy_opens_in_xarray_like_the_batch_output(batch_output, tmp_path):
    import xarray

    assert main(["export", str(batch_output), "-o", str(tmp_path / "all.h5")]) == 0
    with xarray.open_dataset(batch_output, engine="h5netcdf") as virtual, \
            xarray.open_dataset(tmp_path / "all.h5", engine="h5netcdf") as copy:
        assert copy["cubes"].dims == virtual["cubes"].dims and copy["iterations"].dims == virtual["iterations"].dims
        xarray.testing.assert_identical(copy, virtual)


def test_a_frame_of_a_batch_output_exports_alone(batch_output, tmp_path, capsys):
    import xarray

    assert main(["export", str(batch_output), "-o", str(tmp_path / "f3.nc"), "--frame", "3"]) == 2
    assert_one_line_error(capsys, "no frame 3")
    assert main(["export", str(batch_output), "-o", str(tmp_path / "f2.nc"), "--frame", "2"]) == 0
    with h5py.File(batch_output, "r") as f, xarray.open_dataset(tmp_path / "f2.nc", engine="h5netcdf") as ds:
        np.testing.assert_array_equal(ds["cube"].values, f["cubes"][2])
        np.testing.assert_array_equal(ds["wavelength"].values, read_wavelengths(f, 4))
        assert ds.attrs["frame"] == 2


@pytest.mark.parametrize("lost", ["a part", "the parts folder"])
def test_missing_parts_are_refused_with_exit_2_and_no_output(batch_output, tmp_path, capsys, lost):
    output = moved(batch_output, tmp_path)
    parts = output.with_name("out.h5.parts")
    if lost == "a part":
        (parts / "chunk-000002-000003.h5").unlink()
    else:
        shutil.rmtree(parts)
    for name, extra in (("all.h5", []), ("f0.tif", ["--frame", "0"])):
        assert main(["export", str(output), "-o", str(tmp_path / name), *extra]) == 2
        assert_one_line_error(capsys, str(output), "out.h5.parts/",
                              "chunk-000002-000003.h5 is missing" if lost == "a part" else "folder is missing")
        assert nothing_written(tmp_path, name)
    with pytest.raises(InputError, match="reads its frames from out.h5.parts/"):
        check_virtual_sources(output)


def test_check_virtual_sources_passes_whole_batch_outputs_and_plain_files(batch_output, cube_file):
    assert check_virtual_sources(batch_output) == batch_output
    assert check_virtual_sources(cube_file[0]) == cube_file[0]


# ---- the commands ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix, fmt", [(".hdr", "envi"), (".tif", "tiff"), (".nc", "netcdf"), (".png", "png")])
def test_export_takes_the_format_from_the_suffix(cube_file, tmp_path, capsys, suffix, fmt):
    path, _ = cube_file
    output = tmp_path / "out" / f"cube{suffix}"
    assert main(["export", str(path), "-o", str(output)]) == 0
    assert output.exists() and str(output) in capsys.readouterr().out
    assert main(["export", str(path), "-o", str(tmp_path / "named.data"), "--format", fmt]) == 0


def test_show_writes_the_pictures_with_the_truth(cube_file, tmp_path, capsys):
    path, cube = cube_file
    truth = write_cube(tmp_path / "truth.h5", cube * 0.9, WAVELENGTHS)
    assert main(["show", str(path), "--truth", str(truth)]) == 0
    names = ("falsecolour", "projections", "spectra", "convergence")
    printed = capsys.readouterr().out
    for name in names:
        assert (tmp_path / f"cube_{name}.png").stat().st_size > 0 and f"cube_{name}.png" in printed
    assert main(["show", str(truth), "-o", str(tmp_path / "pics" / "t")]) == 0
    assert sorted(p.name for p in (tmp_path / "pics").iterdir()) == sorted(f"t_{n}.png" for n in names[:3])


@pytest.mark.parametrize("flag", ["export", "show"])
def test_help_shows_defaults_and_examples(capsys, flag):
    with pytest.raises(SystemExit):
        main([flag, "--help"])
    text = capsys.readouterr().out
    assert text.count(f"clsdcam {flag} ") >= 2 and "examples:" in text
    assert flag == "show" or "(default: 0)" in text


def bad_cases(cube_file, tmp_path):
    path = str(cube_file[0])
    no_cube = tmp_path / "other.h5"
    with h5py.File(no_cube, "w") as f:
        f["measurement"] = np.zeros((4, 4))
    (tmp_path / "out.tif").mkdir()
    return {
        "unknown format": (["export", path, "-o", str(tmp_path / "out.tif"), "--format", "jpeg"], "--format"),
        "no format from the suffix": (["export", path, "-o", str(tmp_path / "out.xyz")], "out.xyz"),
        "a file without cube": (["export", str(no_cube), "-o", str(tmp_path / "out.nc")], "'cube'"),
        "a cube file to h5": (["export", path, "-o", str(tmp_path / "out.h5")], "not a batch output"),
        "output is a directory": (["export", path, "-o", str(tmp_path / "out.tif")], "is a directory"),
        "missing cube": (["export", str(tmp_path / "none.h5"), "-o", str(tmp_path / "out.png")], "no such file"),
        "show a file without cube": (["show", str(no_cube)], "'cube'"),
        "a NaN cube as a picture": (["export", str(write_cube(tmp_path / "nan.h5", np.full((2, 3, 4), np.nan), [1, 2])),
                                     "-o", str(tmp_path / "out.png")], "nan.h5: cube: 24 non-finite"),
        "truth of another shape": (["show", path, "--truth", str(write_cube(tmp_path / "t.h5", np.ones((2, 3, 4)),
                                                                          [1, 2]))], "does not match"),
    }


@pytest.mark.parametrize("case", ["unknown format", "no format from the suffix", "a file without cube",
                                  "a cube file to h5", "output is a directory", "missing cube",
                                  "show a file without cube", "truth of another shape",
                                  "a NaN cube as a picture"])
def test_bad_input_exits_2_with_one_line_and_writes_nothing(cube_file, tmp_path, capsys, case):
    argv, words = bad_cases(cube_file, tmp_path)[case]
    before = sorted(p.name for p in tmp_path.rglob("*"))
    assert main(argv) == 2
    assert_one_line_error(capsys, words)
    assert sorted(p.name for p in tmp_path.rglob("*")) == before
