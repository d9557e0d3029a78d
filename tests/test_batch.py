"""Many frames: frame sources, one stream, Dask workers (embedded and external), killed workers,
resumed batches and failed frames."""
import os
import signal
import socket
import subprocess
import sys
import threading
import time

import h5py
import numpy as np
import pytest
import tifffile

from clsdcam.batch import BatchSpec, parts_dir, run_batch
from clsdcam.calibration import Calibration, Preprocessing, preprocess
from clsdcam.cli import main
from clsdcam.frames import FrameSource
from clsdcam.solver import Settings, reconstruct
from clsdcam.video import simulate_video, write_video

N_FRAMES = 8


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("video")
    calibration, frames, truth = simulate_video("leds", N_FRAMES, (24, 32), 4, seed=1)
    return write_video(out, calibration, frames, truth)


def spec(video, iters=30, warm=True):
    return BatchSpec(frames=(str(video["frames"]),), calibration=str(video["calibration"]),
                     settings=Settings(iters=iters), warm_start=warm)


def cubes(path):
    with h5py.File(path, "r") as f:
        assert f["cubes"].is_virtual
        return f["cubes"][...], f["iterations"][...], f["error"].asstr()[...]


def cold_reference(video, iters=30):
    """Each frame alone, as ``clsdcam reconstruct`` does it (default preprocessing, cold start)."""
    calibration = Calibration.load(video["calibration"])
    frames = np.load(video["frames"])
    return np.stack([reconstruct(*reversed(preprocess(calibration, frame, Preprocessing())), iters=iters).cube
                     for frame in frames])


def test_frame_sources_agree(video, tmp_path):
    frames = np.load(video["frames"])
    with h5py.File(tmp_path / "stack.h5", "w") as f:
        f["frames"] = frames
    tifffile.imwrite(tmp_path / "stack.tif", frames)
    folder = tmp_path / "folder"
    folder.mkdir()
    for i, frame in enumerate(frames):
        np.save(folder / f"f{i:02d}.npy", frame)
    sources = [FrameSource([str(video["frames"])]), FrameSource([str(tmp_path / "stack.h5")]),
               FrameSource([str(tmp_path / "stack.tif")]), FrameSource([str(folder)]),
               FrameSource(sorted(str(p) for p in folder.iterdir()))]
    for source in sources:
        assert len(source) == N_FRAMES
        np.testing.assert_array_equal(source.read(5), frames[5])


def test_two_dask_workers_match_serial_cold_starts(video, tmp_path):
    summary = run_batch(spec(video, warm=False), tmp_path / "out.h5", workers=2, chunk=3)
    assert summary.computed_frames == N_FRAMES and summary.exit_code == 0
    got, iterations, errors = cubes(tmp_path / "out.h5")
    np.testing.assert_allclose(got, cold_reference(video), rtol=1e-5, atol=1e-6 * got.max())
    assert (iterations == 30).all() and not any(errors)


def test_warm_start_stream_in_process(video, tmp_path):
    summary = run_batch(spec(video, iters=30), tmp_path / "warm.h5", workers=0, chunk=N_FRAMES)
    got, _, _ = cubes(tmp_path / "warm.h5")
    cold = cold_reference(video)
    np.testing.assert_allclose(got[0], cold[0], rtol=1e-5, atol=1e-6 * got.max())  # frame 0 has no predecessor
    assert not np.allclose(got[1:], cold[1:]) and summary.computed_frames == N_FRAMES


def test_resume_computes_only_the_missing_frames(video, tmp_path):
    output = tmp_path / "out.h5"
    run_batch(spec(video), output, workers=0, chunk=2)
    for part in sorted(parts_dir(output).iterdir())[1:3]:  # as if a crash lost two chunks
        part.unlink()
    assert run_batch(spec(video), output, workers=0, chunk=2).computed_frames == 4
    assert run_batch(spec(video), output, workers=0, chunk=2).computed_frames == 0
    assert run_batch(spec(video), output, workers=0, chunk=2, overwrite=True).computed_frames == N_FRAMES
    assert np.isfinite(cubes(output)[0]).all()


def test_a_killed_worker_loses_no_frame(video, tmp_path):
    import logging

    from dask.distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        killer = threading.Timer(1.0, os.kill, (pids[0], signal.SIGKILL))
        killer.start()
        summary = run_batch(spec(video, iters=1500), tmp_path / "out.h5", scheduler=cluster.scheduler_address, chunk=1)
        killer.join()
        assert summary.seconds > 1.0  # the kill came while the batch ran …
        client.wait_for_workers(2, timeout=60)
        assert pids[0] not in client.run(os.getpid).values()  # … and the nanny replaced the killed worker
    got, iterations, errors = cubes(tmp_path / "out.h5")
    assert summary.exit_code == 0 and np.isfinite(got).all() and (iterations == 1500).all()
    assert sorted(p.name for p in parts_dir(tmp_path / "out.h5").iterdir()) == [
        f"chunk-{i:06d}-{i + 1:06d}.h5" for i in range(N_FRAMES)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_external_scheduler_and_worker(video, tmp_path):
    from dask.distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    dask = [sys.executable, "-m", "distributed.cli.dask_scheduler"]
    scheduler = subprocess.Popen(dask + ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                               "--no-dashboard"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        with Client(address, timeout=60) as client:
            client.wait_for_workers(1, timeout=60)
        code = main(["batch", str(video["frames"]), "--calibration", str(video["calibration"]), "-o",
                     str(tmp_path / "out.h5"), "--scheduler", address, "--iters", "20", "--quiet"])
        assert code == 0 and np.isfinite(cubes(tmp_path / "out.h5")[0]).all()
    finally:
        for process in (worker, scheduler):
            process.terminate()
            process.wait(timeout=30)


def test_a_bad_frame_is_recorded_and_the_rest_go_on(video, tmp_path, capsys):
    folder = tmp_path / "frames"
    folder.mkdir()
    frames = np.load(video["frames"])
    frames[3, 2, 2] = np.nan
    for i, frame in enumerate(frames):
        np.save(folder / f"f{i:02d}.npy", frame)
    code = main(["batch", str(folder), "--calibration", str(video["calibration"]), "-o", str(tmp_path / "out.h5"),
                 "--workers", "0", "--iters", "10", "--quiet"])
    assert code == 1
    got, _, errors = cubes(tmp_path / "out.h5")
    assert "non-finite" in errors[3] and np.isnan(got[3]).all()
    assert np.isfinite(np.delete(got, 3, axis=0)).all()
    assert "frame 3" in capsys.readouterr().err
