"""What a new user meets first (issue 36, defects 1, 2, 4, 9 and 10): the shared data found with any install or
named with --data, unwritable outputs and damaged TIFFs as one line and exit 2, output folders created only when
a command writes (and said so in --help), and the smaller wording defects. Everything through ``clsdcam.cli.main``
in-process, at the smallest sizes."""
import errno
import os
import re
import struct
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import h5py
import numpy as np
import pytest

import clsdcam.data
from clsdcam.cli import main
from conftest import TINY
from clsdcam.cli.options import CREATES_FOLDERS
from clsdcam.data import data_folder, locate
from clsdcam.sim import shared_data_dir
from clsdcam.sim.scenes import SAMSON, SAMSON_SHAPE
from clsdcam.sim.sweep import CORNERSTONE

SIZE = TINY


@pytest.fixture(scope="module")
def sim(tiny_sim) -> Path:
    return tiny_sim


def one_line_error(capsys) -> str:
    """The command's stderr, checked to be one 'clsdcam: error:' line without a traceback."""
    err = capsys.readouterr().err.strip()
    assert err.startswith("clsdcam: error:") and "\n" not in err and "Traceback" not in err, err
    return err


def tree(folder: Path) -> set:
    return {p.relative_to(folder) for p in folder.rglob("*")}


# ---- defect 1: the shared data folder ----------------------------------------------------------------------
@pytest.fixture
def no_data_env(monkeypatch):
    monkeypatch.delenv("CLSDCAM_DATA", raising=False)


def layout(root: Path, package: str) -> Path:
    """``root/shared/data`` and a fake ``data.py`` at ``root/package``, as clsdcam.data's ``__file__``."""
    (root / "shared" / "data").mkdir(parents=True)
    module = root / package / "clsdcam" / "data.py"
    module.parent.mkdir(parents=True)
    module.touch()
    return module


def test_a_non_editable_install_finds_the_data_beside_the_clone_it_is_run_from(tmp_path, monkeypatch, no_data_env):
    """pip install . puts the package in the virtual environment: the data is found from the working directory."""
    monkeypatch.setattr(clsdcam.data, "__file__", str(layout(tmp_path, "venv/lib/python3/site-packages")))
    (tmp_path / "clone" / "sub").mkdir(parents=True)
    monkeypatch.chdir(tmp_path / "clone" / "sub")
    assert shared_data_dir() == tmp_path / "shared" / "data" and locate()[1] == "found"


def test_an_editable_install_run_from_elsewhere_finds_the_data_beside_its_clone(tmp_path, monkeypatch, no_data_env):
    monkeypatch.setattr(clsdcam.data, "__file__", str(layout(tmp_path, "clone")))
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    assert shared_data_dir() == tmp_path / "shared" / "data"


def test_data_option_then_environment_then_search(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("CLSDCAM_DATA", str(tmp_path / "env"))
    assert locate() == (tmp_path / "env", "$CLSDCAM_DATA")
    with data_folder(tmp_path / "option"):
        assert locate() == (tmp_path / "option", "--data")
    assert shared_data_dir() == tmp_path / "env"


def fake_samson(root: Path) -> Path:
    """A Samson-shaped cube (int16 BSQ) and its ENVI header under ``root``."""
    path = root / SAMSON
    path.parent.mkdir(parents=True)
    np.arange(np.prod(SAMSON_SHAPE), dtype="<i2").tofile(path)
    wavelengths = ", ".join(f"{w:.1f}" for w in np.linspace(400.9, 899.1, SAMSON_SHAPE[0]))
    path.with_name(path.name + ".hdr").write_text(f"ENVI\nwavelength = {{ {wavelengths} }}\n")
    return root


def test_simulate_reads_the_real_cube_from_the_data_option(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CLSDCAM_DATA", str(tmp_path / "empty"))
    data = fake_samson(tmp_path / "data")
    assert main(["simulate", str(tmp_path / "rc"), "--scene", "realcube", *SIZE, "--data", str(data)]) == 0
    assert "simulated scene 'realcube'" in capsys.readouterr().out
    assert main(["simulate", str(tmp_path / "none"), "--scene", "realcube", *SIZE]) == 2
    err = one_line_error(capsys)
    assert f"{SAMSON} not present in {tmp_path / 'empty'}" in err and "--data DIR" in err
    assert main(["simulate", str(tmp_path / "bad"), "--data", str(tmp_path / "nowhere")]) == 2
    assert "nowhere: no such folder" in one_line_error(capsys)
    assert not (tmp_path / "none").exists() and not (tmp_path / "bad").exists()


def test_analyze_resolution_prints_each_measured_psf_it_skips_and_why(tmp_path, capsys):
    assert main(["analyze", "resolution", str(tmp_path / "a"), "--size", "32x48", "--data", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert (f"  autocorrelation resolution, DiffuserCam tutorial (measured): skipped: "
            f"psf/diffusercam_tutorial_psf_sample.tif not present in {tmp_path} (from --data)") in printed
    assert "Spectral DiffuserScope (measured): skipped" in printed


def test_analyze_resolution_measures_a_psf_from_the_data_option(tmp_path, capsys):
    (tmp_path / "psf").mkdir()
    y, x = np.mgrid[:40, :56]
    np.save(tmp_path / "psf" / "spectraldiffuserscope_psf.npy", np.exp(-((y - 20) ** 2 + (x - 28) ** 2) / 8.0))
    assert main(["analyze", "resolution", str(tmp_path / "a"), "--size", "32x48", "--data", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"Spectral DiffuserScope \(measured\): [\d.]+ px = ", printed)
    assert "DiffuserCam tutorial (measured): skipped" in printed
    assert (tmp_path / "a" / "resolution_spectraldiffuserscope_psf.png").exists()


def test_the_simulated_sweep_uses_the_lamp_power_of_the_data_option(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CLSDCAM_DATA", str(tmp_path / "empty"))
    power = tmp_path / "data" / CORNERSTONE
    power.parent.mkdir(parents=True)
    power.write_text("".join(f"{w},{1 + w / 1000}\n" for w in range(350, 901, 10)))
    assert main(["simulate", str(tmp_path / "lab"), "--sweep", *SIZE, "--data", str(tmp_path / "data")]) == 0
    assert f"(power: {power})" in capsys.readouterr().out
    assert main(["simulate", str(tmp_path / "lab2"), "--sweep", *SIZE]) == 0
    assert f"power: a smooth lamp-like curve, {CORNERSTONE} not present in {tmp_path / 'empty'}" in \
        capsys.readouterr().out


# ---- defect 2: an output that cannot be written ------------------------------------------------------------
def commands_writing_under(sim: Path, out: Path) -> dict:
    """Every command that writes, with its output under ``out`` (valid input otherwise)."""
    calibration, measurement, truth = (str(sim / n) for n in ("calibration.h5", "measurement.npy", "truth.h5"))
    sweep = str(sim.parent / "sweep-frames")
    return {"simulate": ["simulate", f"{out}/s", *SIZE],
            "analyze": ["analyze", "resolution", f"{out}/a", "--size", "32x48"],
            "reconstruct": ["reconstruct", measurement, "--calibration", calibration, "-o", f"{out}/o.h5"],
            "reconstruct --png": ["reconstruct", measurement, "--calibration", calibration, "-o", f"{sim}/x.h5",
                                  "--png", f"{out}/p"],
            "batch": ["batch", measurement, "--calibration", calibration, "--workers", "0", "-o", f"{out}/b.h5"],
            "calibrate psf": ["calibrate", "psf", measurement, "-o", f"{out}/c.h5"],
            "calibrate filters": ["calibrate", "filters", sweep, "--wavelengths", "400:410:10", "-o", f"{out}/f.h5"],
            "demo": ["demo", f"{out}/d", *SIZE, "--iters", "1"],
            "export": ["export", truth, "-o", f"{out}/e.tif"],
            "show": ["show", truth, "-o", f"{out}/p"],
            "check": ["check", "--json", f"{out}/c.json"]}


@pytest.mark.parametrize("command", list(commands_writing_under(Path("s"), Path("o"))))
def test_an_output_under_a_file_is_one_line_and_exit_2_for_every_command(sim, tmp_path, capsys, command):
    (tmp_path / "afile").write_text("not a folder")
    before = tree(tmp_path)
    assert main(commands_writing_under(sim, tmp_path / "afile")[command]) == 2
    assert "afile is a file, not a folder" in one_line_error(capsys)
    assert tree(tmp_path) == before


@contextmanager
def read_only(folder: Path):
    """``folder`` unwritable for this user: mode 555, and for root (which ignores modes, as in CI) the immutable
    attribute (``chattr +i``; skipped only where the file system has none)."""
    folder.chmod(0o555)
    immutable = os.access(folder, os.W_OK) and subprocess.run(["chattr", "+i", str(folder)],
                                                              capture_output=True).returncode == 0
    try:
        if os.access(folder, os.W_OK) and not immutable:
            pytest.skip("root, and no immutable attribute on this file system")
        yield folder
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(folder)], check=True)
        folder.chmod(0o755)


@pytest.mark.parametrize("command", ["simulate", "analyze", "reconstruct"])
def test_a_read_only_output_folder_is_one_line_and_exit_2(sim, tmp_path, capsys, command):
    (tmp_path / "ro").mkdir()
    with read_only(tmp_path / "ro") as locked:
        assert main(commands_writing_under(sim, locked)[command]) == 2
        assert "cannot write there: " in one_line_error(capsys) and not any(locked.iterdir())


def test_a_file_system_error_during_a_command_is_one_line_and_exit_2(tmp_path, monkeypatch, capsys):
    """The command line's own handler: a write refused after the checks (a disk that became read-only)."""
    def refuse(outdir, _sim):
        raise PermissionError(errno.EACCES, "Permission denied", f"{outdir}/truth.h5")

    monkeypatch.setattr("clsdcam.sim.write_simulation", refuse)
    assert main(["simulate", str(tmp_path / "s"), *SIZE]) == 2
    assert one_line_error(capsys).endswith(f"{tmp_path}/s/truth.h5: Permission denied")


# ---- defect 4: a truncated TIFF -----------------------------------------------------------------------------
@pytest.mark.parametrize("command", ["reconstruct", "calibrate psf"])
def test_a_truncated_tiff_is_one_line_that_says_so_without_tifffile_logging(sim, tmp_path, capsys, command):
    tiff = tmp_path / "cut.tif"
    tiff.write_bytes(b"II*\x00" + struct.pack("<I", 1_000_000) + bytes(64))   # first page past the end
    args = {"reconstruct": ["reconstruct", str(tiff), "--calibration", str(sim / "calibration.h5")],
            "calibrate psf": ["calibrate", "psf", str(tiff)]}[command]
    assert main([*args, "-o", str(tmp_path / "o.h5")]) == 2
    err = one_line_error(capsys)
    assert "cut.tif: not a readable image (no image data: truncated or damaged file)" in err and "tifffile" not in err


# ---- defect 9: output folders are created, only when written -------------------------------------------------
WRITERS = [["reconstruct"], ["batch"], ["calibrate", "psf"], ["calibrate", "filters"], ["simulate"], ["demo"],
           ["export"], ["show"], ["analyze", "resolution"], ["check"]]


@pytest.mark.parametrize("command", WRITERS, ids=" ".join)
def test_help_of_every_output_says_missing_folders_are_created(capsys, command):
    with pytest.raises(SystemExit):
        main([*command, "--help"])
    assert CREATES_FOLDERS in " ".join(capsys.readouterr().out.split())


def test_missing_output_folders_are_created_when_written_and_not_on_bad_input(sim, tmp_path, capsys):
    calibration = str(sim / "calibration.h5")
    nan = tmp_path / "nan.npy"
    np.save(nan, np.where(np.arange(24 * 32).reshape(24, 32) == 5, np.nan, 1.0))
    assert main(["reconstruct", str(nan), "--calibration", calibration, "-o", str(tmp_path / "new/sub/o.h5")]) == 2
    assert main(["calibrate", "psf", str(nan), "-o", str(tmp_path / "new/sub/c.h5")]) == 2
    assert main(["simulate", str(tmp_path / "new/sub"), *SIZE, "--noise", "-1"]) == 2
    for solver_option in (["--converge", "0"], ["--tv", "-1"]):    # refused before the demo writes its simulation
        assert main(["demo", str(tmp_path / "new/sub"), *SIZE, *solver_option]) == 2
    assert not (tmp_path / "new").exists()
    assert main(["reconstruct", str(sim / "measurement.npy"), "--calibration", calibration, "--iters", "1",
                 "--quiet", "-o", str(tmp_path / "new/sub/o.h5")]) == 0
    assert (tmp_path / "new" / "sub" / "o.h5").is_file()


# ---- defect 10: wording ----------------------------------------------------------------------------------------
def test_analyze_resolution_help_shows_its_own_options_and_a_plain_percent(capsys):
    with pytest.raises(SystemExit):
        main(["analyze", "resolution", "--help"])
    text = capsys.readouterr().out
    assert "70 %" in text and "%%" not in text and "--data" in text
    assert not any(option in text for option in ("--recon-size", "--iters", "--trials", "--bands"))


def test_the_skip_summary_says_what_was_cut(sim, tmp_path, capsys):
    args = [str(sim / "measurement.npy"), "--calibration", str(sim / "calibration.h5"), "--iters", "1", "--quiet"]
    assert main(["reconstruct", *args, "-o", str(tmp_path / "full.h5"), "--no-skip"]) == 0
    assert "field: none cut: 48×64 (the paper's)" in capsys.readouterr().out
    assert main(["reconstruct", *args, "-o", str(tmp_path / "cut.h5"), "--support-field"]) == 0
    printed = capsys.readouterr().out
    assert "field: 48×60 instead of 48×64 (6% of the paper's field cut;" in printed and "of the voxels" not in printed


def test_filters_that_are_not_a_stack_say_so(sim, tmp_path, capsys):
    bad = tmp_path / "flat.h5"
    with h5py.File(bad, "w") as f:
        f["psf"], f["filters"], f["wavelengths"] = np.ones((24, 32)), np.ones((24, 32)), [500.0]
    assert main(["reconstruct", str(sim / "measurement.npy"), "--calibration", str(bad), "-o", str(tmp_path / "o.h5")]) == 2
    assert "filters must be 3-D (K, 24, 32) for the 24×32 psf, found 2-D shape 24×32" in one_line_error(capsys)


def test_one_non_finite_value_is_singular(sim, tmp_path, capsys):
    nan = tmp_path / "nan.npy"
    np.save(nan, np.where(np.arange(24 * 32).reshape(24, 32) == 33, np.nan, 1.0))
    assert main(["reconstruct", str(nan), "--calibration", str(sim / "calibration.h5"), "-o", str(tmp_path / "o.h5")]) == 2
    assert "nan.npy: 1 non-finite value (NaN/Inf), first at (1, 1)" in one_line_error(capsys)


def test_dir_lists_the_public_api_without_importing_it():
    code = ("import sys, clsdcam; names = dir(clsdcam); "
            "print(all(n in names for n in clsdcam.__all__), 'clsdcam.solve.solver' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["True", "False"]
