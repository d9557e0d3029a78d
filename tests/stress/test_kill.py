"""Killing a writer (SIGKILL, no chance to clean up) leaves the output path with nothing, the old
file, or a complete new file — never a partial one."""
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from clsdcam.cli import main

WRITER = """
import sys, numpy as np
from clsdcam.io import write_cube
cube = np.ones((48, 512, 512), np.float32)
sys.stdout.write("ready\\n"); sys.stdout.flush()
write_cube(sys.argv[1], cube, np.arange(48.0), [{"iteration": 1}], {"note": "new"})
"""


def temp_files(directory, name):
    return [p for p in directory.iterdir() if p.name.startswith(f".{name}.")]


def kill_when_temp_appears(process, directory, name, timeout=60.0) -> bool:
    """SIGKILL ``process`` as soon as its temporary output exists; True if that happened mid-write."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline and process.poll() is None:
        if temp_files(directory, name):
            process.send_signal(signal.SIGKILL)
            process.wait()
            return True
        time.sleep(0.0005)
    process.wait()
    return False


def assert_old_or_complete(path, old_note):
    with h5py.File(path, "r") as f:
        note = f.attrs["note"]
        assert note in (old_note, "new")
        if note == "new":
            assert f["cube"].shape == (48, 512, 512) and float(f["cube"][-1, -1, -1]) == 1.0


@pytest.mark.stress
def test_sigkill_mid_write_keeps_the_old_file(tmp_path):
    output = tmp_path / "out.h5"
    with h5py.File(output, "w") as f:
        f["cube"] = np.zeros((1, 2, 2), np.float32)
        f.attrs["note"] = "old"
    process = subprocess.Popen([sys.executable, "-c", WRITER, str(output)], stdout=subprocess.PIPE)
    process.stdout.readline()
    assert kill_when_temp_appears(process, tmp_path, output.name), "the writer finished before the kill"
    assert process.returncode == -signal.SIGKILL
    assert_old_or_complete(output, "old")
    with h5py.File(output, "r") as f:
        assert f.attrs["note"] == "old"


@pytest.mark.stress
@pytest.mark.parametrize("delay", [0.0, 0.3, 1.0, 2.0])
def test_sigkill_of_a_reconstruction_at_any_moment_leaves_nothing_or_a_complete_file(tmp_path, delay):
    sim_dir = tmp_path / "sim"
    assert main(["simulate", str(sim_dir), "--size", "32x40", "--bands", "4", "--scene", "leds"]) == 0
    output = tmp_path / "cube.h5"
    process = subprocess.Popen([sys.executable, "-m", "clsdcam.cli", "reconstruct", str(sim_dir / "measurement.npy"),
                                "--calibration", str(sim_dir / "calibration.h5"), "-o", str(output), "--iters", "200",
                                "--quiet"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    time.sleep(delay)
    process.send_signal(signal.SIGKILL)
    process.wait()
    if output.exists():
        with h5py.File(output, "r") as f:
            assert f["cube"].shape == (4, 32, 40) and f.attrs["iterations"] == 200


def wait_for_progress(process):
    """Read stderr (a pipe: progress comes as lines, the first after iteration 1) up to the first progress line;
    fail, rather than wait for ever, if the process ends first."""
    for line in process.stderr:
        if line.startswith("clsdcam: iteration "):
            return
    pytest.fail(f"the reconstruction ended (exit {process.wait()}) before any progress line")


@pytest.mark.stress
@pytest.mark.parametrize("save", [False, True])
def test_ctrl_c_writes_the_best_cube_only_when_asked(tmp_path, save):
    sim_dir = tmp_path / "sim"
    assert main(["simulate", str(sim_dir), "--size", "32x40", "--bands", "4", "--scene", "leds"]) == 0
    output = tmp_path / "cube.h5"
    args = [sys.executable, "-m", "clsdcam.cli", "reconstruct", str(sim_dir / "measurement.npy"), "--calibration",
            str(sim_dir / "calibration.h5"), "-o", str(output), "--iters", "1000000"]
    process = subprocess.Popen(args + (["--save-on-interrupt"] if save else []), stderr=subprocess.PIPE, text=True)
    wait_for_progress(process)
    process.send_signal(signal.SIGINT)
    err = process.communicate(timeout=60)[1]
    assert process.returncode == 130 and "Traceback" not in err
    assert output.exists() == save
    if save:
        assert "best cube so far" in err
        with h5py.File(output, "r") as f:
            assert f.attrs["stop_reason"] == "interrupted" and 0 < f.attrs["iterations"] < 1000000
            assert np.isfinite(f["cube"][...]).all()
    assert not temp_files(tmp_path, output.name)
