"""What a reconstruction says and writes at its end (issue 36): a poor fit blamed on a short solve or on the
calibration, as the history shows; --save-on-interrupt's pictures; the backend ``auto`` chooses and says."""
import sys
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from clsdcam.backends import cl_devices, get_backend, resolve_backend
from clsdcam.cli import main
from clsdcam.cli.solve import LEVELLED, TAIL, ProgressBar, data_fall, poor_fit_warning, stop_text
from clsdcam.errors import InputError
from clsdcam.solve.settings import CONVERGE, CONVERGE_WIDE

SMALL = ["--size", "32x40", "--bands", "4", "--scene", "leds"]
MEDIUM = ["--size", "64x96", "--bands", "16", "--scene", "leds"]     # 5 iterations: fit 42%, 9.3× the noise
CALIBRATION_DOUBT = "is the calibration the camera's"
RUN_LONGER = "with the fit still improving"


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    """Three simulations: ``medium`` (leds 64×96×16, seed 3), ``small`` and ``other`` (leds 32×40×4, seeds 3 and 9:
    the same camera model, another camera's calibration)."""
    out = tmp_path_factory.mktemp("scenes")
    for name, options in {"medium": MEDIUM + ["--seed", "3"], "small": SMALL + ["--seed", "3"],
                          "other": SMALL + ["--seed", "9"]}.items():
        assert main(["simulate", str(out / name), *options]) == 0
    return out


def reconstruct(scenes, measured: str, calibrated: str, output, *extra):
    return main(["reconstruct", str(scenes / measured / "measurement.npy"), "--calibration",
                 str(scenes / calibrated / "calibration.h5"), "-o", str(output), *extra])


def warnings(err: str) -> list[str]:
    return [line for line in err.splitlines() if "warning" in line]


# ---- defect 7: a short solve is told to run longer; a levelled-off poor fit puts the calibration in doubt ----------
def test_a_short_solve_is_told_to_run_longer_not_to_doubt_the_calibration(scenes, tmp_path, capsys):
    assert reconstruct(scenes, "medium", "medium", tmp_path / "c.h5", "--iters", "5", "--quiet") == 0
    [warning] = warnings(capsys.readouterr().err)
    assert "the solve stopped after 5 iterations " + RUN_LONGER in warning and "run more iterations" in warning
    assert CALIBRATION_DOUBT not in warning


@pytest.mark.parametrize("given, says", [((), "--converge auto: {:.2g}"), (("--converge", "0.07"), "--converge {:g}")])
def test_the_stop_line_says_the_tolerance_the_solve_stopped_at(scenes, tmp_path, capsys, given, says):
    """``--converge auto`` says what auto came to (the cube's ``stop_tolerance``), a tolerance given is said as it is."""
    assert reconstruct(scenes, "small", "small", tmp_path / "c.h5", "--quiet", *given) == 0
    with h5py.File(tmp_path / "c.h5", "r") as f:
        tolerance, converge = f.attrs["stop_tolerance"], f.attrs["converge"]
    assert converge == (float(given[1]) if given else "auto")
    assert tolerance == 0.07 if given else tolerance in (CONVERGE, CONVERGE_WIDE)
    assert f"by its own estimate ({says.format(tolerance)})" in capsys.readouterr().out


@pytest.mark.parametrize("converge, tolerance, says", [("auto", 0.0087123, "--converge auto: 0.0087"),
                                                       ("auto", 0.1, "--converge auto: 0.1"),
                                                       (0.0087123, 0.0087123, "--converge 0.0087123")])
def test_the_stop_line_rounds_an_automatic_tolerance_and_keeps_a_given_one(converge, tolerance, says):
    """A tolerance auto came to (a few points' narrowed one) is said to two digits, one the user gave as given."""
    result = SimpleNamespace(stop_reason="converged", attrs={"distance_estimate": 0.0081, "stop_tolerance": tolerance,
                                                             "converge": converge})
    assert stop_text(result) == f"converged, about 0.81% from the converged cube by its own estimate ({says})"


def interrupt_at(monkeypatch, iteration: int):
    """Ctrl-C during the progress callback of ``iteration`` (the driver turns it into the stop "interrupted")."""
    update = ProgressBar.update

    def update_then_interrupt(self, record):
        update(self, record)
        if record["iteration"] == iteration:
            raise KeyboardInterrupt

    monkeypatch.setattr(ProgressBar, "update", update_then_interrupt)


def test_an_interrupted_solve_is_told_to_run_longer(scenes, tmp_path, monkeypatch, capsys):
    interrupt_at(monkeypatch, 6)
    assert reconstruct(scenes, "medium", "medium", tmp_path / "c.h5", "--save-on-interrupt") == 130
    [warning] = warnings(capsys.readouterr().err)
    assert "the solve was interrupted after 6 iterations " + RUN_LONGER in warning
    assert CALIBRATION_DOUBT not in warning


def test_another_cameras_calibration_still_puts_the_calibration_in_doubt(scenes, tmp_path, capsys):
    """60 iterations with another camera's calibration: the fit has levelled off (the data term fell 1.1% over the
    last 10 iterations), 72% of the measurement is unexplained: the calibration is doubted, no advice to run on."""
    assert reconstruct(scenes, "small", "other", tmp_path / "c.h5", "--iters", "60", "--quiet") == 0
    [warning] = warnings(capsys.readouterr().err)
    assert CALIBRATION_DOUBT in warning and RUN_LONGER not in warning
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert data_fall([{"data": d} for d in f["history/data"][...]]) < LEVELLED


def history(*data: float) -> list[dict]:
    return [{"data": d} for d in data]


def test_the_trend_is_read_over_the_last_iterations():
    assert data_fall(history(5.0)) is None                                  # one iteration: no trend yet
    assert data_fall(history(4.0, 1.0)) == pytest.approx(0.75)
    assert data_fall(history(100.0, *[2.0] * TAIL, 1.0)) == pytest.approx(0.5)   # the first record is out of reach
    assert data_fall(history(1.0, 1.5)) < 0                                  # a rise: not improving


@pytest.mark.parametrize("data, says", [((5.0,), RUN_LONGER), ((4.0, 1.0), RUN_LONGER),
                                        ((1.0, *[0.999] * TAIL), CALIBRATION_DOUBT)])
def test_the_warning_follows_the_trend(data, says):
    result = SimpleNamespace(history=history(*data), iterations=len(data), stop_reason="iterations")
    assert says in poor_fit_warning(result, 0.5)


# ---- defect 8: --save-on-interrupt with --png writes the pictures too ---------------------------------------------
def test_save_on_interrupt_writes_the_pictures_of_the_saved_cube(scenes, tmp_path, monkeypatch, capsys):
    interrupt_at(monkeypatch, 3)
    prefix = tmp_path / "pic"
    assert reconstruct(scenes, "small", "small", tmp_path / "c.h5", "--save-on-interrupt", "--png", str(prefix)) == 130
    printed = capsys.readouterr()
    assert sorted(p.name for p in tmp_path.glob("pic_*.png")) == [
        "pic_convergence.png", "pic_falsecolour.png", "pic_projections.png", "pic_spectra.png"]
    assert "pictures: " in printed.out and f"and its pictures to {prefix}_*.png" in printed.err
    with h5py.File(tmp_path / "c.h5", "r") as f:
        assert f.attrs["stop_reason"] == "interrupted" and f.attrs["iterations"] == 3


def test_without_save_on_interrupt_nothing_is_written(scenes, tmp_path, monkeypatch):
    interrupt_at(monkeypatch, 3)
    assert reconstruct(scenes, "small", "small", tmp_path / "c.h5", "--png", str(tmp_path / "pic")) == 130
    assert not list(tmp_path.iterdir())


# ---- defect 11: --backend auto (the default) -----------------------------------------------------------------------
def fake_opencl(monkeypatch, *kinds: str, failures: dict[str, str] | None = None):
    """OpenCL as pyopencl would show it, with one device of each kind ("CPU", "GPU"): no real pyopencl needed. Each
    compiles, but those ``failures`` names ("Fake GPU" -> the compiler's error)."""
    device_type = SimpleNamespace(CPU=2, GPU=4)
    platform = SimpleNamespace(name="Fake OpenCL")
    devices = [(platform, SimpleNamespace(type=getattr(device_type, kind), name=f"Fake {kind}", platform=platform))
               for kind in kinds]
    monkeypatch.setattr(cl_devices, "import_pyopencl", lambda: SimpleNamespace(device_type=device_type))
    monkeypatch.setattr(cl_devices, "all_devices", lambda: devices)
    monkeypatch.setattr(cl_devices, "build_failure", lambda device: (failures or {}).get(device.name, ""))
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)


def test_a_device_whose_compiler_fails_here_is_passed_over_for_one_that_builds(monkeypatch):
    """PoCL 3.0's LLVM 14 lists a Zen 5 CPU but cannot compile for it: the next device that builds is chosen, even
    where the one that cannot is the preferred kind."""
    fake_opencl(monkeypatch, "GPU", "CPU", failures={"Fake GPU": "error: unknown target CPU 'generic'"})
    assert cl_devices.choose_device().name == "Fake CPU"


@pytest.mark.parametrize("named", [None, "GPU"])
def test_no_device_that_builds_is_one_line_saying_why(monkeypatch, named):
    fake_opencl(monkeypatch, "GPU", "CPU", failures={"Fake GPU": "error: unknown target CPU 'generic'",
                                                     "Fake CPU": "error: no compiler"})
    with pytest.raises(InputError, match=r"Fake GPU \(Fake OpenCL\) cannot compile kernels on this machine "
                                         r"\(error: unknown target CPU 'generic'\); use --backend numpy") as raised:
        cl_devices.choose_device(named)
    assert "\n" not in str(raised.value)


def test_auto_is_numpy_here_and_gives_numpys_cube(scenes, tmp_path, capsys):
    """On a machine without an OpenCL GPU (this one: PoCL's CPU device at most), the default is NumPy, said in one
    line, and its cube is --backend numpy's, bit for bit."""
    if cl_devices.find_gpu() is not None:
        pytest.skip("this machine has an OpenCL GPU")
    common = ("--iters", "5", "--quiet")
    assert reconstruct(scenes, "small", "small", tmp_path / "auto.h5", *common) == 0
    assert "backend: numpy (auto: no OpenCL GPU)\n" in capsys.readouterr().out
    assert reconstruct(scenes, "small", "small", tmp_path / "numpy.h5", *common, "--backend", "numpy") == 0
    assert "backend:" not in capsys.readouterr().out
    with h5py.File(tmp_path / "auto.h5", "r") as auto, h5py.File(tmp_path / "numpy.h5", "r") as numpy:
        assert auto.attrs["backend"] == "numpy" and np.array_equal(auto["cube"][...], numpy["cube"][...])


def test_auto_chooses_an_opencl_gpu_and_says_which(scenes, tmp_path, monkeypatch, capsys):
    """With a GPU among the OpenCL devices, the default asks the solver for OpenCL (here the fake GPU is not
    built: the solver gets NumPy under that name)."""
    import clsdcam.solve.solver
    from clsdcam.backends.numpy import NumpyBackend

    fake_opencl(monkeypatch, "CPU", "GPU")
    asked = []
    monkeypatch.setattr(clsdcam.solve.solver, "get_backend", lambda name, dtype, *rest: asked.append(name) or
                        NumpyBackend(dtype))
    assert reconstruct(scenes, "small", "small", tmp_path / "c.h5", "--iters", "2", "--quiet") == 0
    assert "backend: opencl on Fake GPU (Fake OpenCL) (auto: a GPU was found)\n" in capsys.readouterr().out
    assert asked == ["opencl"]


def test_auto_gives_admm_the_gpu_and_numpy_to_an_algorithm_without_opencl(scenes, tmp_path, monkeypatch, capsys):
    """ADMM runs on OpenCL: ``--backend auto`` asks for the GPU as for FISTA. An algorithm whose ``backends`` leave
    OpenCL out (ADMM made so here) gets NumPy, said in one line, and solves."""
    import clsdcam.solve.solver
    from clsdcam.algorithms.admm import Admm
    from clsdcam.backends.numpy import NumpyBackend

    fake_opencl(monkeypatch, "GPU")
    asked = []
    monkeypatch.setattr(clsdcam.solve.solver, "get_backend", lambda name, dtype, *rest: asked.append(name) or
                        NumpyBackend(dtype))
    common = ("--iters", "3", "--algorithm", "admm", "--quiet")
    assert reconstruct(scenes, "small", "small", tmp_path / "gpu.h5", *common) == 0
    assert "(auto: a GPU was found)" in capsys.readouterr().out and asked == ["opencl"]
    monkeypatch.setattr(Admm, "backends", ("numpy",), raising=False)
    assert reconstruct(scenes, "small", "small", tmp_path / "a.h5", *common) == 0
    assert "backend: numpy (auto: --algorithm admm runs on NumPy)\n" in capsys.readouterr().out
    with h5py.File(tmp_path / "a.h5", "r") as f:
        assert f.attrs["algorithm"] == "admm" and f.attrs["iterations"] == 3 and asked == ["opencl", "numpy"]


@pytest.mark.parametrize("kinds", [(), ("CPU",)])
def test_auto_leaves_cpu_opencl_devices_opt_in(monkeypatch, kinds):
    fake_opencl(monkeypatch, *kinds)
    assert resolve_backend("auto") == ("numpy", "no OpenCL GPU")
    assert resolve_backend("auto", device="Fake") == ("opencl", "--device given")


def test_auto_without_pyopencl_is_numpy(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyopencl", None)      # import pyopencl raises ImportError
    assert cl_devices.find_gpu() is None
    assert resolve_backend("auto") == ("numpy", "no OpenCL GPU") and get_backend("auto").name == "numpy"
    assert resolve_backend("numpy") == ("numpy", "") and resolve_backend("opencl") == ("opencl", "")


def test_devices_says_what_auto_chooses(capsys):
    """``clsdcam devices`` ends with the line a solve with the default backend prints."""
    pytest.importorskip("pyopencl")
    try:
        cl_devices.list_devices()
    except InputError:
        pytest.skip("no OpenCL device")
    assert main(["devices"]) == 0
    on = None if cl_devices.find_gpu() is None else cl_devices.describe(cl_devices.choose_device())
    assert capsys.readouterr().out.splitlines()[-1] == ("backend: numpy (auto: no OpenCL GPU)" if on is None else
                                                        f"backend: opencl on {on} (auto: a GPU was found)")


def test_batch_says_what_auto_chose(scenes, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(cl_devices, "find_gpu", lambda: None)
    frames = tmp_path / "frames.npy"
    np.save(frames, np.stack([np.load(scenes / "small" / "measurement.npy")] * 2))
    assert main(["batch", str(frames), "--calibration", str(scenes / "small" / "calibration.h5"), "-o",
                 str(tmp_path / "b.h5"), "--workers", "0", "--iters", "2", "--cold-iters", "2", "--quiet"]) == 0
    assert "backend: numpy (auto: no OpenCL GPU)\n" in capsys.readouterr().out
