"""A batch's checks and layout: every frame to compute is checked before any work (any source: .npy, HDF5 or
TIFF stacks, folders of files; a stack in bounded blocks; a resume only the frames still missing), and the
worker processes × threads chosen so that they never exceed the cores, said in the output, and reaching each
worker's solver, BLAS and pocl."""
import os

import h5py
import numpy as np
import pytest
import threadpoolctl
import tifffile

from clsdcam.backends.blocks import THREADS_VARIABLE, available_cores, host_threads
from clsdcam.backends.numpy import NumpyBackend
from clsdcam.batch import FrameSource, frames, parts_dir, stream, workers
from clsdcam.batch.workers import Layout, plan_workers
from clsdcam.camera.calibration import Preprocessing
from clsdcam.cli import main
from clsdcam.errors import InputError
from clsdcam.io import read_wavelengths
from clsdcam.sim.video import simulate_video, write_video
from clsdcam.solve.solver import Settings, Solver

N_FRAMES, BAD = 6, (1, 2, 3)  # the bad value: frame 1, pixel (y, x) = (2, 3)


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    calibration, stack, truth = simulate_video("leds", N_FRAMES, (16, 20), 2, seed=3)
    return write_video(tmp_path_factory.mktemp("video"), calibration, stack, truth)


def with_nan(video, folder, kind):
    """The video's frames with one NaN at BAD, as ``kind``: a .npy, HDF5 or TIFF stack, or a folder of .npy files."""
    stack = np.load(video["frames"])
    stack[BAD] = np.nan
    folder.mkdir()
    if kind == "folder":
        for i, frame in enumerate(stack):
            np.save(folder / f"f{i:02d}.npy", frame)
        return folder
    path = folder / f"nan.{kind}"
    if kind == "npy":
        np.save(path, stack)
    elif kind == "h5":
        with h5py.File(path, "w") as f:
            f["frames"] = stack
    else:
        tifffile.imwrite(path, stack)
    return path


def batch(frames_path, video, output, *options):
    return ["batch", str(frames_path), "--calibration", str(video["calibration"]), "-o", str(output), "--quiet",
            "--iters", "3", *options]


def refuse_solving(monkeypatch):
    def solve(self, *args, **kwargs):
        raise AssertionError("a frame was solved")

    monkeypatch.setattr(Solver, "solve", solve)


@pytest.mark.parametrize("kind, options", [("npy", ()), ("h5", ("--workers", "0")), ("tiff", ("--workers", "0")),
                                           ("folder", ("--workers", "0"))])
def test_a_nan_in_any_frame_source_is_refused_before_any_work(video, tmp_path, monkeypatch, capsys, kind, options):
    """Issue 36, defect 3: ``clsdcam batch nan.npy --calibration …`` solved the other frames, exited 1 and left
    nan.h5 and nan.h5.parts/; now exit 2, one line naming the frame and its first bad pixel, nothing written."""
    source = with_nan(video, tmp_path / "in", kind)
    refuse_solving(monkeypatch)
    assert main(batch(source, video, tmp_path / "nan.h5", *options)) == 2
    err = capsys.readouterr().err
    named = "f01.npy" if kind == "folder" else "frame 1 of"
    assert err.startswith("clsdcam: error: ") and len(err.splitlines()) == 1, err
    assert named in err and "first at (2, 3)" in err and "non-finite" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["in"]


def test_an_unreadable_frame_file_is_refused_before_any_work(video, tmp_path, monkeypatch, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    for i, frame in enumerate(np.load(video["frames"])):
        np.save(folder / f"f{i:02d}.npy", frame)
    (folder / "f04.npy").write_bytes(b"not a numpy file")
    refuse_solving(monkeypatch)
    assert main(batch(folder, video, tmp_path / "out.h5", "--workers", "0")) == 2
    err = capsys.readouterr().err
    assert "f04.npy" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out.h5").exists() and not parts_dir(tmp_path / "out.h5").exists()


def false_truth(video, path, change):
    """The video's truth.h5 copied to ``path`` with ``change`` made: fewer frames, one band more, other pixels,
    other wavelengths."""
    with h5py.File(video["truth"], "r") as f:
        cubes, wavelengths = f["cubes"][...], read_wavelengths(f, 0)
    changed = {"frames": (cubes[:-1], wavelengths), "pixels": (cubes[..., :-2], wavelengths),
               "bands": (np.concatenate([cubes, cubes[:, :1]], axis=1), np.append(wavelengths, 900.0)),
               "wavelengths": (cubes, wavelengths + 20.0)}[change]
    with h5py.File(path, "w") as f:
        f["cubes"], f["wavelength"] = changed
    return path


@pytest.mark.parametrize("change, message", [
    ("frames", "5 true cubes for 6 frames"), ("bands", "3 bands where the calibration gives 2"),
    ("pixels", "true cubes of 16×18 pixels for reconstructions of 16×20"),
    ("wavelengths", "its wavelengths 534–790 nm are not the calibration's (514–770 nm)")])
def test_a_truth_that_does_not_match_the_frames_is_refused_before_any_work(video, tmp_path, monkeypatch, capsys,
                                                                           change, message):
    """``batch --truth``: one line naming the truth and what differs, exit 2, nothing written."""
    truth = false_truth(video, tmp_path / "truth.h5", change)
    refuse_solving(monkeypatch)
    assert main(batch(video["frames"], video, tmp_path / "out.h5", "--workers", "0", "--truth", str(truth))) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"clsdcam: error: --truth {truth}: {message}") and len(err.splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["truth.h5"]


def test_a_stack_is_checked_block_by_block(video, tmp_path, monkeypatch):
    """Memory stays one block (here 2 frames' bytes) whatever the stack's length; the bad frame is still found."""
    stack = np.load(video["frames"]).astype(np.float32)
    stack[5, 7, 9] = np.inf
    np.save(tmp_path / "s.npy", stack)
    source = FrameSource([str(tmp_path / "s.npy")])
    assert source.frame_bytes == stack[0].nbytes
    monkeypatch.setattr(frames, "CHECK_BYTES", 2 * stack[0].nbytes + 1)
    read, block = [], frames._read_stack_block
    monkeypatch.setattr(frames, "_read_stack_block", lambda path, s, e: read.append((s, e)) or block(path, s, e))
    with pytest.raises(InputError, match=r"frame 5 of .*first at \(7, 9\)"):
        source.check(range(N_FRAMES))
    assert read == [(0, 2), (2, 4), (4, 6)]
    read.clear()
    source.check([0, 1, 2, 4])  # only the frames asked for, each run cut into blocks
    assert read == [(0, 2), (2, 3), (4, 5)]


def test_a_resume_checks_only_the_frames_still_to_compute(video, tmp_path, capsys):
    stack = np.load(video["frames"])
    np.save(tmp_path / "v.npy", stack)
    output = tmp_path / "out.h5"
    assert main(batch(tmp_path / "v.npy", video, output, "--workers", "0", "--chunk", "3")) == 0
    (parts_dir(output) / "chunk-000003-000006.h5").unlink()
    stack[0, 0, 0] = np.nan  # a frame already computed: not read again
    np.save(tmp_path / "v.npy", stack)
    assert main(batch(tmp_path / "v.npy", video, output, "--workers", "0")) == 0
    stack[4, 1, 1] = np.nan  # a frame still to compute
    np.save(tmp_path / "v.npy", stack)
    (parts_dir(output) / "chunk-000003-000006.h5").unlink()
    assert main(batch(tmp_path / "v.npy", video, output, "--workers", "0")) == 2
    assert "frame 4 of" in capsys.readouterr().err


@pytest.mark.parametrize("asked, cores, processes, threads, text", [
    (1, 2, 1, 2, "1 worker × 2 threads on 2 cores"),
    (2, 2, 2, 1, "2 workers × 1 thread on 2 cores"),
    (4, 2, 2, 1, "2 workers × 1 thread on 2 cores (--workers 4: no more processes than cores)"),
    (3, 16, 3, 5, "3 workers × 5 threads on 16 cores"),
    (2, 1, 1, 1, "1 worker × 1 thread on 1 core (--workers 2: no more processes than cores)"),
])
def test_worker_processes_times_threads_never_exceed_the_cores(asked, cores, processes, threads, text):
    layout = plan_workers(asked, cores=cores)
    assert (layout.processes, layout.threads, str(layout)) == (processes, threads, text)
    assert all(plan_workers(w, cores=c).processes * plan_workers(w, cores=c).threads <= c
               for w in range(1, 9) for c in range(1, 17))


def test_in_process_and_external_layouts(monkeypatch):
    monkeypatch.setenv(THREADS_VARIABLE, "3")
    assert str(plan_workers(0, cores=4)) == "this process × 3 threads on 4 cores"
    assert "tcp://h:1" in str(plan_workers(1, "tcp://h:1", cores=4)) and plan_workers(1, "tcp://h:1").processes == 0


def test_host_threads_come_from_clsdcam_threads_or_the_cores(monkeypatch):
    monkeypatch.delenv(THREADS_VARIABLE, raising=False)
    assert host_threads() == available_cores() == NumpyBackend().workers
    monkeypatch.setenv(THREADS_VARIABLE, "3")
    assert host_threads() == NumpyBackend().workers == 3 and NumpyBackend(workers=5).workers == 5
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv(THREADS_VARIABLE, bad)
        with pytest.raises(InputError, match=THREADS_VARIABLE):
            host_threads()


def threads_seen_by_a_chunk(calibration: str, shape):
    """On a worker, as ``_dask_chunk`` runs a chunk: (its solver's host threads, BLAS threads, pocl's setting,
    glibc's trim threshold)."""
    with workers.chunk_threads():
        solver, _ = stream.cached_solver(calibration, Preprocessing(), Settings(iters=1), "numpy", None, "auto",
                                         "auto", shape)
        blas = [i["num_threads"] for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
        environ = os.environ.get
        return solver.backend.workers, blas, environ("POCL_MAX_PTHREAD_COUNT"), environ(workers.MALLOC_TRIM)


def test_the_chosen_threads_reach_each_worker(video, monkeypatch):
    """Worker processes started as a batch starts them get the layout's threads in their solver, BLAS and pocl
    (3 here, neither Dask's default of one BLAS thread nor the machine's cores), and no MALLOC_TRIM_THRESHOLD_
    (Dask's default; here also left in this process's environment, as an earlier LocalCluster leaves it)."""
    monkeypatch.setenv(workers.MALLOC_TRIM, "65536")
    shape = np.load(video["frames"]).shape[1:]
    with workers.connect(Layout(processes=2, threads=3, cores=6, asked=2)) as client:
        seen = client.run(threads_seen_by_a_chunk, str(video["calibration"]), shape)
    assert len(seen) == 2
    for solver_threads, blas, pocl, trim in seen.values():
        assert solver_threads == 3 and pocl == "3" and (not blas or set(blas) == {3}) and trim is None
    assert os.environ[workers.MALLOC_TRIM] == "65536"  # this process's environment is given back


def test_the_batch_says_where_its_frames_ran(video, tmp_path, monkeypatch, capsys):
    """Issue 36, defect 6: the printed output names the processes × threads chosen."""
    monkeypatch.setattr(workers, "available_cores", lambda: 2)
    monkeypatch.setenv(THREADS_VARIABLE, "2")
    assert main(batch(video["frames"], video, tmp_path / "two.h5", "--workers", "2")) == 0
    assert "on 2 workers × 1 thread on 2 cores)" in capsys.readouterr().out
    assert main(batch(video["frames"], video, tmp_path / "none.h5", "--workers", "0")) == 0
    assert "on this process × 2 threads on 2 cores)" in capsys.readouterr().out


def test_auto_workers_take_one_gpu_each_and_numpy_without_opencl(monkeypatch):
    """``--backend auto`` (the default) spreads embedded workers over the GPUs as ``opencl`` does; without OpenCL
    a worker gets no device (``auto`` becomes NumPy) instead of an error."""
    import distributed

    from clsdcam.backends import cl_devices

    class Types:
        GPU, CPU = 4, 2

    gpus = [type("Device", (), {"type": Types.GPU})() for _ in range(2)]
    monkeypatch.delenv("PYOPENCL_CTX", raising=False)
    monkeypatch.setattr(distributed, "get_worker", lambda: type("Worker", (), {"name": "3"})())
    monkeypatch.setattr(cl_devices, "import_pyopencl", lambda: type("cl", (), {"device_type": Types})())
    cpu = type("Device", (), {"type": Types.CPU})()
    monkeypatch.setattr(cl_devices, "all_devices", lambda: [(0, gpus[0]), (1, cpu), (2, gpus[1])])
    assert stream._worker_device("auto", None) is gpus[1] and stream._worker_device("opencl", None) is gpus[1]
    assert stream._worker_device("numpy", None) is None and stream._worker_device("auto", "gfx") == "gfx"

    def no_opencl():
        raise InputError("no OpenCL platform")

    monkeypatch.setattr(cl_devices, "all_devices", no_opencl)
    assert stream._worker_device("auto", None) is None
