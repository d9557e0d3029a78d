"""The command line: simulate → reconstruct round trip, demo, and bad input (exit 2, one line, no output)."""
import subprocess
import sys

import h5py
import numpy as np
import pytest
from conftest import opencl_device

from clsdcam.cli import main
from clsdcam.cli.solve import NOT_NOISE

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
    """--no-skip is the full solver (paper field, every band); --rank forces the subspace; both say so; --subspace
    and --support-field reach the settings (the default leaves both off)."""
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
        assert not fast.attrs["subspace"] and not fast.attrs["support_field"]
        assert tuple(fast.attrs["field_shape"]) == (64, 80)
    assert main(["reconstruct", *args, "-o", str(tmp_path / "auto.h5"), "--subspace", "--support-field"]) == 0
    with h5py.File(tmp_path / "auto.h5", "r") as chosen:
        assert chosen.attrs["subspace"] and chosen.attrs["support_field"]


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
    opencl_device()
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


def test_devices_without_an_opencl_driver_says_so_and_that_auto_runs_numpy(monkeypatch, capsys):
    """The core install has no OpenCL driver: ``clsdcam devices`` says so in one line, names the install, and ends
    with the backend the default then runs (exit 0: nothing found is its answer)."""
    from clsdcam.backends import cl_devices
    from clsdcam.errors import InputError

    def no_platform():
        raise InputError(f"no OpenCL platform found (clGetPlatformIDs failed); {cl_devices.INSTALL_HINT}")

    monkeypatch.setattr(cl_devices, "all_devices", no_platform)
    assert main(["devices"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("no OpenCL platform found") and "clsdcam[pocl]" in lines[0]
    assert lines[-1] == "backend: numpy (auto: no OpenCL GPU)"


def every_help_command() -> list[list[str]]:
    """Every command and sub-choice, as the argument list that asks for its help."""
    from clsdcam.cli.analyze import ANALYSES
    from clsdcam.cli.options import commands

    return [[]] + [[c] for c in commands()] + [["analyze", a] for a in ANALYSES + ("all",)]


@pytest.mark.parametrize("command", every_help_command(), ids=lambda c: " ".join(c) or "clsdcam")
def test_every_help_works_and_shows_examples(command, capsys):
    with pytest.raises(SystemExit) as exit_:
        main([*command, "--help"])
    assert exit_.value.code == 0
    text = capsys.readouterr().out
    assert "usage: clsdcam" in text
    if len(command) == 1:
        assert "examples:" in text
    if len(command) == 1 and command[0] not in ("devices", "analyze") or len(command) == 2:
        assert "default" in text


def test_batch_help_lists_only_what_batch_takes(capsys):
    with pytest.raises(SystemExit):
        main(["batch", "--help"])
    text = capsys.readouterr().out
    assert not any(flag in text for flag in ("--png", "--full-field", "--saturation"))


def test_a_bad_number_names_the_option_not_an_internal_type(simulated, tmp_path, capsys):
    assert run_reconstruct(simulated, tmp_path / "o.h5", "--tv", "abc") == 2
    err = capsys.readouterr().err
    assert "--tv" in err and "'abc' is not a number or auto" in err and "_number" not in err


def test_bare_command_lists_the_commands(capsys):
    assert main([]) == 2
    err = capsys.readouterr().err.strip()
    assert "reconstruct" in err and "demo" in err and "\n" not in err


def test_version_and_python_m(tmp_path):
    import clsdcam

    out = subprocess.run([sys.executable, "-m", "clsdcam", "--version"], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == f"clsdcam {clsdcam.__version__}"


def test_scene_names_are_the_simulators():
    from clsdcam.cli.options import SCENES
    from clsdcam.sim import SCENES as SIMULATED

    assert set(SCENES) == set(SIMULATED)


@pytest.mark.parametrize("where", ["directory", "unwritable", "pictures"])
def test_an_unusable_output_is_refused_before_any_work(simulated, tmp_path, capsys, monkeypatch, where):
    """-o naming a directory or an unwritable place, or an unwritable picture prefix: exit 2 with one line
    before the solve starts (it used to fail after the whole solve, with a traceback)."""
    import clsdcam.solve.solver

    monkeypatch.setattr(clsdcam.solve.solver.Solver, "solve", lambda *a, **k: pytest.fail("solved before the check"))
    output = {"directory": tmp_path, "unwritable": "/proc/nope/cube.h5", "pictures": tmp_path / "ok.h5"}[where]
    extra = ["--png", "/proc/nope/pic"] if where == "pictures" else []
    assert run_reconstruct(simulated, output, *extra) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("clsdcam: error:") and "\n" not in err and not (tmp_path / "ok.h5").exists()


def test_a_closed_pipe_does_not_stop_the_work_or_print_a_traceback(tmp_path):
    """``clsdcam … | head`` with the reader gone before the output: no BrokenPipeError traceback, the files
    are written and the exit code is 0."""
    process = subprocess.Popen([sys.executable, "-m", "clsdcam", "simulate", str(tmp_path / "s"), "--size", "24x32",
                                "--bands", "3"], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    process.stdout.close()
    _, err = process.communicate(timeout=120)
    assert process.returncode == 0 and b"Traceback" not in err and b"BrokenPipe" not in err
    assert (tmp_path / "s" / "measurement.npy").exists()


def test_progress_in_a_log_is_lines_not_a_redrawn_bar(tmp_path):
    """stderr not a terminal: progress lines (every LOG_EVERY seconds, and one at the end), no carriage returns."""
    assert main(["simulate", str(tmp_path / "s"), "--size", "24x32", "--bands", "3", "--scene", "leds"]) == 0
    process = subprocess.run([sys.executable, "-m", "clsdcam", "reconstruct", str(tmp_path / "s" / "measurement.npy"),
                              "--calibration", str(tmp_path / "s" / "calibration.h5"), "-o", str(tmp_path / "c.h5"),
                              "--iters", "12"], capture_output=True, text=True, timeout=120)
    assert process.returncode == 0 and "\r" not in process.stderr
    lines = [line for line in process.stderr.splitlines() if line.startswith("clsdcam: iteration")]
    assert lines and lines[-1].startswith("clsdcam: iteration 12/12")


def test_a_calibration_that_does_not_fit_is_reported(simulated, tmp_path, capsys):
    """Every reconstruction reports ‖Av − b‖/‖b‖ (stored); a calibration of the right size but another camera's
    runs to completion but warns in one line."""
    assert main(["simulate", str(tmp_path / "other"), *SMALL, "--scene", "leds", "--seed", "9"]) == 0
    assert run_reconstruct(simulated, tmp_path / "right.h5", "--iters", "60") == 0
    right = capsys.readouterr()
    assert "fit: ‖Av − b‖/‖b‖" in right.out and "warning" not in right.err
    assert main(["reconstruct", str(simulated / "measurement.npy"), "--calibration", str(tmp_path / "other" / "calibration.h5"),
                 "-o", str(tmp_path / "wrong.h5"), "--quiet", "--iters", "60"]) == 0
    wrong = capsys.readouterr()
    assert "warning: the cube leaves" in wrong.err and wrong.err.count("\n") == 1
    with h5py.File(tmp_path / "right.h5", "r") as r, h5py.File(tmp_path / "wrong.h5", "r") as w:
        assert r.attrs["relative_residual"] < 0.1 < w.attrs["relative_residual"]   # measured: 0.054 and 0.72
        assert r.attrs["residual_to_noise"] < NOT_NOISE < w.attrs["residual_to_noise"]


def test_point_sources_with_their_own_calibration_are_not_reported(tmp_path, capsys):
    """Point sources leave the most unfitted structure of the simulator's scenes (‖Av − b‖/‖b‖ 0.25, rms(r)/σ̂ 4.0
    after 60 iterations at 64×96×16): no warning (with pixel-difference noise and a threshold of 2.3, there was)."""
    assert main(["simulate", str(tmp_path / "s"), "--size", "64x96", "--bands", "16", "--scene", "sources"]) == 0
    assert main(["reconstruct", str(tmp_path / "s" / "measurement.npy"), "--calibration",
                 str(tmp_path / "s" / "calibration.h5"), "-o", str(tmp_path / "c.h5"), "--quiet", "--iters", "60"]) == 0
    assert "warning" not in capsys.readouterr().err
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f.attrs["relative_residual"] > 0.1 and f.attrs["residual_to_noise"] < NOT_NOISE


def test_a_noisy_measurement_with_the_right_calibration_is_not_reported(tmp_path, capsys):
    """A residual that is mostly noise (high ‖Av − b‖/‖b‖, rms near the noise level) is no sign of a wrong
    calibration: no warning."""
    assert main(["simulate", str(tmp_path / "s"), *SMALL, "--scene", "leds", "--noise", "1e-3"]) == 0
    assert main(["reconstruct", str(tmp_path / "s" / "measurement.npy"), "--calibration",
                 str(tmp_path / "s" / "calibration.h5"), "-o", str(tmp_path / "c.h5"), "--quiet", "--iters", "60"]) == 0
    assert "warning" not in capsys.readouterr().err
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f.attrs["relative_residual"] > 0.1 and f.attrs["residual_to_noise"] < NOT_NOISE
