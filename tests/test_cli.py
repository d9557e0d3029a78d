"""The command line: simulate → reconstruct round trip, demo, and bad input (exit 2, one line, no output)."""
import subprocess
import sys

import h5py
import numpy as np
import pytest

from clsdcam.cli import main

SMALL = ["--size", "32x40", "--bands", "4"]


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim")
    assert main(["simulate", str(out), *SMALL, "--scene", "leds", "--seed", "3"]) == 0
    return out


def run_reconstruct(simulated, output, *extra):
    return main(["reconstruct", str(simulated / "measurement.npy"), "--calibration", str(simulated / "calibration.h5"),
                 "-o", str(output), "--quiet", *extra])


def test_reconstruct_writes_cube_history_attrs_and_pictures(simulated, tmp_path, capsys):
    output = tmp_path / "cube.h5"
    code = run_reconstruct(simulated, output, "--iters", "15", "--png", str(tmp_path / "pic"),
                           "--truth", str(simulated / "truth.h5"))
    assert code == 0
    printed = capsys.readouterr().out
    assert "PSNR" in printed and "spectral angle" in printed
    with h5py.File(output, "r") as f:
        assert f["cube"].shape == (4, 32, 40) and f["cube"].dtype == np.float32
        assert f["wavelength"].shape == (4,) and f["wavelength"].attrs["units"] == "nm"
        assert len(f["history/objective"]) == 15 and len(f["history/seconds"]) == 15
        assert f.attrs["iterations"] == 15 and f.attrs["backend"] == "numpy"
        assert f.attrs["stop_reason"] == "iterations"
    assert sorted(p.name for p in tmp_path.glob("pic_*.png")) == [
        "pic_convergence.png", "pic_falsecolour.png", "pic_projections.png", "pic_spectra.png"]


def bad_cases(simulated, tmp_path):
    meas, cal = str(simulated / "measurement.npy"), str(simulated / "calibration.h5")
    nan = tmp_path / "nan.npy"
    data = np.load(meas)
    data[3, 5] = np.nan
    np.save(nan, data)
    wrong = tmp_path / "wrong.npy"
    np.save(wrong, np.ones((10, 12), np.float32))
    return {
        "missing calibration": [meas, "--calibration", str(tmp_path / "nope.h5")],
        "missing measurement": [str(tmp_path / "nope.npy"), "--calibration", cal],
        "nan measurement": [str(nan), "--calibration", cal],
        "wrong shape": [str(wrong), "--calibration", cal],
        "negative tv": [meas, "--calibration", cal, "--tv", "-1"],
        "zero iterations": [meas, "--calibration", cal, "--iters", "0"],
        "non-numeric tv": [meas, "--calibration", cal, "--tv", "abc"],
        "unknown backend": [meas, "--calibration", cal, "--backend", "cuda"],
        "bad tv weights": [meas, "--calibration", cal, "--tv-weights", "1,2"],
        "unknown device": [meas, "--calibration", cal, "--backend", "opencl", "--device", "no-such-device"],
        "unknown fft engine": [meas, "--calibration", cal, "--fft", "fftw"],
        "negative lowrank": [meas, "--calibration", cal, "--lowrank", "-0.1"],
        "truth of the wrong shape": [meas, "--calibration", cal, "--truth", cal],
        "negative rank": [meas, "--calibration", cal, "--rank", "-2"],
        "negative plateau": [meas, "--calibration", cal, "--plateau", "-1e-3"],
    }


@pytest.mark.parametrize("case", ["missing calibration", "missing measurement", "nan measurement", "wrong shape",
                                  "negative tv", "zero iterations", "non-numeric tv", "unknown backend",
                                  "bad tv weights", "unknown device", "unknown fft engine", "negative lowrank",
                                  "truth of the wrong shape", "negative rank", "negative plateau"])
def test_bad_input_exits_2_with_one_line_and_no_output(simulated, tmp_path, capsys, case):
    output = tmp_path / "out.h5"
    args = bad_cases(simulated, tmp_path)[case]
    assert main(["reconstruct", "--iters", "3", "--quiet", "-o", str(output), *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("clsdcam: error:") and "\n" not in err and "Traceback" not in err
    assert not output.exists() and not list(tmp_path.glob(".out.h5*"))


def test_skip_options_reach_the_solver_and_the_report_is_printed(tmp_path, capsys):
    """--no-skip is the full solver (paper field, every band); --rank forces the subspace; both say so."""
    sim = tmp_path / "sim"
    assert main(["simulate", str(sim), "--size", "32x40", "--bands", "16", "--scene", "leds"]) == 0
    args = [str(sim / "measurement.npy"), "--calibration", str(sim / "calibration.h5"), "--quiet", "--iters", "20"]
    assert main(["reconstruct", *args, "-o", str(tmp_path / "full.h5"), "--no-skip"]) == 0
    assert "(the paper's)" in capsys.readouterr().out
    assert main(["reconstruct", *args, "-o", str(tmp_path / "r2.h5"), "--rank", "2", "--plateau", "1e-12"]) == 0
    printed = capsys.readouterr().out
    assert "skipped:" in printed and "2 spectral basis vectors instead of 16 bands" in printed
    with h5py.File(tmp_path / "full.h5", "r") as full, h5py.File(tmp_path / "r2.h5", "r") as fast:
        assert tuple(full.attrs["field_shape"]) == (64, 80) and not full.attrs["skip"]
        assert set(full["history/rank"][:]) == {16} and set(fast["history/rank"][10:]) == {2}
        assert fast.attrs["rank"] == 2 and fast.attrs["plateau"] == 1e-12 and fast.attrs["fft_work_saved"] > 0


def test_console_entry_point_reports_bad_input_without_traceback(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "clsdcam.cli", "reconstruct", str(tmp_path / "x.npy"),
                           "--calibration", str(tmp_path / "c.h5"), "-o", str(tmp_path / "o.h5")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr and proc.stderr.count("\n") == 1


def test_demo_prints_accuracy_and_time(tmp_path, capsys):
    assert main(["demo", str(tmp_path / "demo"), "--size", "40x48", "--bands", "6", "--iters", "20", "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "PSNR" in printed and "s/iteration" in printed
    assert (tmp_path / "demo" / "cube.h5").exists() and (tmp_path / "demo" / "cube_falsecolour.png").exists()


@pytest.mark.opencl
def test_opencl_backend_reaches_the_numpy_psnr(simulated, tmp_path, capsys):
    pytest.importorskip("pyopencl")
    psnr = {}
    for backend in ("numpy", "opencl"):
        assert run_reconstruct(simulated, tmp_path / f"{backend}.h5", "--iters", "40", "--backend", backend,
                               "--truth", str(simulated / "truth.h5")) == 0
        psnr[backend] = float(capsys.readouterr().out.split("PSNR ")[1].split(" dB")[0])
        with h5py.File(tmp_path / f"{backend}.h5", "r") as f:
            assert f.attrs["backend"] == backend and f.attrs["fft_engine"]
    assert abs(psnr["opencl"] - psnr["numpy"]) <= 0.05


def test_devices_lists_the_opencl_devices(capsys):
    pytest.importorskip("pyopencl")
    assert main(["devices"]) == 0
    assert "fp64" in capsys.readouterr().out
