"""Many frames: frame sources, one stream, Dask workers (embedded and external), killed workers,
resumed and interrupted batches, failed frames, unwritable outputs, the output's provenance and
dimension scales, the command's help."""
import dataclasses
import json
import logging
import os
import pickle
import socket
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import tifffile
import xarray
from distributed import Client, LocalCluster
from distributed.diagnostics.plugin import WorkerPlugin

from clsdcam.batch import BatchSpec, FrameSource, parts, parts_dir, run_batch, stream
from clsdcam.camera.calibration import Calibration, PixelMask, Preprocessing, preprocess
from clsdcam.cli import main
from clsdcam.errors import InputError
from clsdcam.algorithms.fista import Fista
from clsdcam.metrics import peak_ratio, psnr, spectral_angle
from clsdcam.provenance import provenance, sha256
from clsdcam.sim.video import simulate_video, write_video
from clsdcam.solve.solver import Settings, Solver, reconstruct

N_FRAMES = 8
SOLVE = Solver.solve


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("video")
    calibration, frames, truth = simulate_video("leds", N_FRAMES, (24, 32), 4, seed=1)
    return write_video(out, calibration, frames, truth)


def spec(video, iters=30, warm=True, cold_iters=None):
    return BatchSpec(frames=(str(video["frames"]),), calibration=str(video["calibration"]),
                     settings=Settings(iters=iters), warm_start=warm, cold_iters=cold_iters)


def cubes(path):
    with h5py.File(path, "r") as f:
        assert f["cubes"].is_virtual
        return f["cubes"][...], f["iterations"][...], f["error"].asstr()[...]


def local_cluster():
    return LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                        silence_logs=logging.CRITICAL)


def command(video, output, *options):
    """``clsdcam batch`` on the video's frames, in this process, quiet."""
    return ["batch", str(video["frames"]), "--calibration", str(video["calibration"]), "-o", str(output),
            "--workers", "0", "--quiet", *options]


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
    with pytest.raises(InputError, match="not found"):
        FrameSource([str(folder / "f00.npy"), str(folder / "missing.npy")])


def test_two_dask_workers_match_serial_cold_starts(video, tmp_path):
    counted = []
    summary = run_batch(spec(video, warm=False), tmp_path / "out.h5", workers=2, chunk=3, progress=counted.append)
    assert summary.computed_frames == N_FRAMES and summary.exit_code == 0 and sum(counted) == N_FRAMES
    got, iterations, errors = cubes(tmp_path / "out.h5")
    np.testing.assert_allclose(got, cold_reference(video), rtol=1e-5, atol=1e-6 * got.max())
    assert (iterations == 30).all() and not any(errors)


def test_warm_start_stream_in_process(video, tmp_path):
    summary = run_batch(spec(video, iters=30, cold_iters=30), tmp_path / "warm.h5", workers=0, chunk=3)
    got, _, _ = cubes(tmp_path / "warm.h5")
    cold = cold_reference(video)
    np.testing.assert_allclose(got[0], cold[0], rtol=1e-5, atol=1e-6 * got.max())  # frame 0 has no predecessor
    assert not np.allclose(got[1:], cold[1:]) and summary.computed_frames == N_FRAMES


def test_resume_computes_only_the_missing_frames(video, tmp_path):
    output = tmp_path / "out.h5"
    run_batch(spec(video), output, workers=0, chunk=2)
    for part in sorted(parts_dir(output).glob("chunk-*.h5"))[1:3]:  # as if a crash lost two chunks (frames 2–5)
        part.unlink()
    counted = []
    assert run_batch(spec(video), output, workers=0, chunk=3, progress=counted.append).computed_frames == 4
    assert sum(counted) == 4  # another chunk size still computes only frames 2–5
    assert sorted(p.name for p in parts_dir(output).glob("chunk-*.h5"))[1:3] == [
        "chunk-000002-000005.h5", "chunk-000005-000006.h5"]
    assert run_batch(spec(video), output, workers=0, chunk=2).computed_frames == 0
    assert np.isfinite(cubes(output)[0]).all()
    with pytest.raises(InputError, match="another batch"):  # other settings never mix with these parts
        run_batch(spec(video, iters=20), output, workers=0)
    assert run_batch(spec(video, iters=20), output, workers=0, overwrite=True).computed_frames == N_FRAMES


def test_an_interrupted_batch_resumes(video, tmp_path, monkeypatch):
    """Ctrl-C (a KeyboardInterrupt while frame 5 is read) keeps the finished chunks and nothing else."""
    output, read = tmp_path / "out.h5", stream._read

    def interrupted(source, i):
        if i == 5:
            raise KeyboardInterrupt
        return read(source, i)

    monkeypatch.setattr(stream, "_read", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_batch(spec(video), output, workers=0, chunk=2)
    monkeypatch.setattr(stream, "_read", read)
    assert not output.exists() and not [p for p in parts_dir(output).iterdir() if p.name.startswith(".")]
    assert run_batch(spec(video), output, workers=0, chunk=2).computed_frames == 4


def test_a_resume_removes_stale_temporaries_and_keeps_finished_parts(video, tmp_path):
    """Temporaries left by a killed writer (or Ctrl-C on Dask workers) are removed when the batch resumes."""
    output = tmp_path / "out.h5"
    run_batch(spec(video), output, workers=0, chunk=2)
    folder = parts_dir(output)
    (folder / "chunk-000002-000004.h5").unlink()
    stale = [folder / ".chunk-000002-000004.h5.0badf00d.h5", folder / ".chunk-000004-000006.h5.1234abcd.h5"]
    for path in stale:
        path.write_bytes(b"half an HDF5 file")
    (folder / ".notes").write_text("not a part's temporary")
    assert run_batch(spec(video), output, workers=0, chunk=2).computed_frames == 2
    assert sorted(p.name for p in folder.iterdir()) == [".notes", "batch.json"] + [
        f"chunk-{s:06d}-{s + 2:06d}.h5" for s in range(0, N_FRAMES, 2)]
    assert np.isfinite(cubes(output)[0]).all()


def interrupt_after(monkeypatch, frames):
    """Solver.solve raises KeyboardInterrupt (Ctrl-C) once ``frames`` frames were solved."""
    solved = []

    def solve(self, *args, **kwargs):
        if len(solved) == frames:
            raise KeyboardInterrupt
        solved.append(True)
        return SOLVE(self, *args, **kwargs)

    monkeypatch.setattr(Solver, "solve", solve)


def test_ctrl_c_says_how_many_frames_were_kept(video, tmp_path, monkeypatch, capsys):
    output = tmp_path / "out.h5"
    interrupt_after(monkeypatch, 0)
    assert main(command(video, output, "--chunk", "2", "--iters", "10")) == 130
    assert capsys.readouterr().err == "clsdcam: interrupted; no output written\n"
    assert not parts_dir(output).exists()
    interrupt_after(monkeypatch, 2)  # after the first chunk
    assert main(command(video, output, "--chunk", "2", "--iters", "10")) == 130
    assert capsys.readouterr().err == (f"clsdcam: interrupted; 2 of {N_FRAMES} frames kept in "
                                       f"{parts_dir(output.resolve())}/ — run the same command again to finish\n")
    assert not output.exists()
    monkeypatch.setattr(Solver, "solve", SOLVE)
    assert main(command(video, output, "--chunk", "2", "--iters", "10")) == 0
    assert f"{N_FRAMES} frames ({N_FRAMES - 2} computed now" in capsys.readouterr().out


def test_a_ctrl_c_the_solver_caught_stops_the_batch(video, tmp_path, monkeypatch):
    """FISTA turns Ctrl-C into the stop reason "interrupted"; in a batch that frame is not done and the batch stops."""
    iterate, calls = Fista.iterate, []

    def interrupted(self, *args):
        calls.append(True)
        if len(calls) == 15:  # in frame 1, of 10 iterations each
            raise KeyboardInterrupt
        return iterate(self, *args)

    monkeypatch.setattr(Fista, "iterate", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_batch(spec(video, iters=10), tmp_path / "out.h5", workers=0, chunk=2)
    assert not parts_dir(tmp_path / "out.h5").exists()


def test_an_unwritable_output_is_refused_before_any_frame_is_read(video, tmp_path, monkeypatch, capsys):
    def unread(source, i):
        raise AssertionError("a frame was read")

    monkeypatch.setattr(stream, "_read", unread)
    folder, taken = tmp_path / "cubes.h5", tmp_path / "other.h5.parts"
    folder.mkdir()
    taken.write_text("a file where the parts folder would go")
    for output, why in ((folder, "is a directory"), ("/proc/nope.h5", "cannot write there"),
                        (tmp_path / "other.h5", "cannot write there")):
        assert main(command(video, output)) == 2
        err = capsys.readouterr().err
        assert err.startswith("clsdcam: error: ") and why in err and len(err.splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["cubes.h5", "other.h5.parts"] and not any(folder.iterdir())


def test_the_output_has_provenance_and_dimension_scales(video, tmp_path):
    """Like a single cube: the inputs' SHA-256, preprocessing, command line…, and dims (frame, wavelength, y, x)."""
    output = tmp_path / "out.h5"
    run_batch(spec(video, iters=5), output, workers=0)
    with xarray.open_dataset(output, engine="h5netcdf") as ds:
        assert ds["cubes"].dims == ("frame", "wavelength", "y", "x") and ds["iterations"].dims == ("frame",)
        np.testing.assert_array_equal(ds["wavelength"], Calibration.load(video["calibration"]).wavelengths)
        assert ds["wavelength"].attrs["units"] == "nm" and np.isfinite(ds["cubes"].values).all()
    with h5py.File(output, "r") as f:
        attrs = dict(f.attrs)
    expected = provenance({"frames": video["frames"].resolve(), "calibration": video["calibration"].resolve()},
                          Preprocessing())
    assert {k: attrs[k] for k in expected if k != "created"} == {k: v for k, v in expected.items() if k != "created"}
    assert attrs["frames_sha256"] == sha256(video["frames"]) and attrs["warm_start"] and "settings" in attrs


def test_a_truth_gives_each_frames_accuracy_in_the_summary_and_the_output(video, tmp_path, capsys):
    """Issue 48: ``batch --truth`` prints and stores each frame's PSNR, mean spectral angle and peak ratio: those of
    the written cube against its true cube."""
    output = tmp_path / "out.h5"
    assert main(command(video, output, "--iters", "5", "--truth", str(video["truth"]))) == 0
    printed = capsys.readouterr().out
    written, iterations, _ = cubes(output)
    with h5py.File(video["truth"], "r") as f:
        truth = f["cubes"][...]
    with h5py.File(output, "r") as f:
        attrs, warm = dict(f.attrs), f["warm"][...]
    assert attrs["truth_path"] == str(video["truth"].resolve()) and attrs["truth_sha256"] == sha256(video["truth"])
    lines = printed.split(f"against {video['truth']}:\n")[1].splitlines()
    assert len(lines) == N_FRAMES and warm.sum() == N_FRAMES - 1
    for i, line in enumerate(lines):
        direct = psnr(written[i], truth[i]), spectral_angle(written[i], truth[i]), peak_ratio(written[i], truth[i])
        assert (attrs["psnr"][i], attrs["spectral_angle"][i], attrs["peak_ratio"][i]) == direct
        assert line == (f"  frame {i}: {'warm' if warm[i] else 'cold'}, {iterations[i]} iteration"
                        f"{'s' * (int(iterations[i]) != 1)}: PSNR {direct[0]:.2f} dB, "
                        f"mean spectral angle {direct[1]:.2f}°, peak ratio {direct[2]:.3f}")


def test_batch_help_shows_defaults_and_ends_with_examples(capsys):
    with pytest.raises(SystemExit) as done:
        main(["batch", "--help"])
    text = capsys.readouterr().out
    assert done.value.code == 0 and "(default: 1)" in text and "(default: auto)" in text
    options, examples = text.split("\nexamples:\n")
    assert "--dead-pixels" in options and 2 <= examples.count("clsdcam batch ") <= 3
    assert not any(flag in text for flag in ("--png", "--full-field", "--saturation"))


class KillOnce(WorkerPlugin):
    """Kills its worker process (os._exit) twice in a batch, once per marker file: when a chunk task
    starts, then when a chunk task has written its part but its worker has not yet reported it."""

    def __init__(self, folder):
        self.folder = Path(folder)

    def transition(self, key, start, finish, **kwargs):
        running, finished = self.folder / "killed-running", self.folder / "killed-finished"
        marker = {"executing": running, "memory": finished}.get(finish)
        if "clsdcam-chunk" in str(key) and marker and not marker.exists() and (marker is running or running.exists()):
            marker.write_text(str(os.getpid()))
            os._exit(1)


def test_killed_workers_lose_no_frame_and_write_none_twice(video, tmp_path):
    output = tmp_path / "out.h5"
    with local_cluster() as cluster, Client(cluster) as client:
        client.register_plugin(KillOnce(tmp_path))
        summary = run_batch(spec(video), output, scheduler=cluster.scheduler_address, chunk=1)
    assert summary.exit_code == 0 and np.isfinite(cubes(output)[0]).all()
    parts = sorted(parts_dir(output).glob("chunk-*.h5"))
    assert [p.name for p in parts] == [f"chunk-{i:06d}-{i + 1:06d}.h5" for i in range(N_FRAMES)]
    writers = [h5py.File(p, "r").attrs["writer"].split(":")[-1] for p in parts]
    assert (tmp_path / "killed-running").read_text() not in writers
    # the part of the worker killed before it reported was kept (Dask re-ran the task; it wrote nothing)
    assert (tmp_path / "killed-finished").read_text() in writers


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_external_scheduler_and_worker(video, tmp_path):
    """``dask scheduler`` and ``dask worker`` as the user starts them; shut down by the client."""
    address = f"tcp://127.0.0.1:{free_port()}"
    dask = [sys.executable, "-m", "dask"]
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen(dask + ["scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                                         "--no-dashboard"], **quiet)
    worker = subprocess.Popen(dask + ["worker", address, "--nthreads", "1", "--no-dashboard"], **quiet)
    try:
        with Client(address, timeout=60) as client:
            client.wait_for_workers(1, timeout=60)
        code = main(["batch", str(video["frames"]), "--calibration", str(video["calibration"]), "-o",
                     str(tmp_path / "out.h5"), "--scheduler", address, "--iters", "20", "--quiet"])
        assert code == 0 and np.isfinite(cubes(tmp_path / "out.h5")[0]).all()
        with Client(address, timeout=60, set_as_default=False) as client:  # shutdown() would leave dask's
            client.shutdown()                                               # default scheduler set to this one
        assert scheduler.wait(timeout=30) == 0 and worker.wait(timeout=30) == 0
    finally:
        for process in (worker, scheduler):
            if process.poll() is None:
                process.kill()
                process.wait()


def test_a_frame_damaged_during_the_run_is_recorded_and_the_rest_go_on(video, tmp_path, capsys, monkeypatch):
    """Every frame is checked before the run (tests/test_batch_checks.py); frames 3 and 6, damaged after that
    check, fail with their reasons and the others go on; against the truth they have no figures."""
    folder = tmp_path / "frames"
    folder.mkdir()
    frames = np.load(video["frames"])
    for i, frame in enumerate(frames):
        np.save(folder / f"f{i:02d}.npy", frame)
    read = stream._read

    def damaged_on_the_way(source, i):
        if i == 3:
            np.save(folder / "f03.npy", np.where(np.eye(*frames[3].shape, k=0, dtype=bool), np.nan, frames[3]))
            (folder / "f06.npy").write_bytes(b"not a numpy file")
        return read(source, i)

    monkeypatch.setattr(stream, "_read", damaged_on_the_way)
    code = main(["batch", str(folder), "--calibration", str(video["calibration"]), "-o", str(tmp_path / "out.h5"),
                 "--workers", "0", "--iters", "10", "--quiet", "--truth", str(video["truth"])])
    assert code == 1
    got, _, errors = cubes(tmp_path / "out.h5")
    assert "non-finite" in errors[3] and "f06.npy" in errors[6] and np.isnan(got[[3, 6]]).all()
    assert np.isfinite(np.delete(got, [3, 6], axis=0)).all()
    printed = capsys.readouterr()
    assert "frame 3" in printed.err and "  frame 3: failed\n" in printed.out and "  frame 6: failed\n" in printed.out
    with h5py.File(tmp_path / "out.h5", "r") as f:
        psnrs = f.attrs["psnr"]
    assert np.isnan(psnrs[[3, 6]]).all() and np.isfinite(np.delete(psnrs, [3, 6])).all()


def test_simulate_frames_writes_a_video(tmp_path):
    assert main(["simulate", str(tmp_path / "v"), "--frames", "3", "--size", "16x20", "--bands", "2", "--scene", "leds"]) == 0
    frames = np.load(tmp_path / "v" / "frames.npy")
    with h5py.File(tmp_path / "v" / "truth.h5", "r") as f:
        truth = f["cubes"][...]
    assert frames.shape == (3, 16, 20) and truth.shape == (3, 2, 16, 20)
    assert not np.allclose(truth[0], truth[2])  # the scene moves


def test_the_fingerprint_hashes_canonical_json_not_pickle(monkeypatch):
    """batch.json's fingerprint is the same for equal specs on any Python or NumPy (no pickle bytes) and differs
    when anything that decides the cubes differs; its settings text holds every Settings field."""
    def no_pickle(*args, **kwargs):
        raise AssertionError("the fingerprint must not depend on pickle")

    monkeypatch.setattr(pickle, "dumps", no_pickle)

    def stamp(iters=30, dead=PixelMask.of(np.eye(3)), n=2):
        return parts.stamp(BatchSpec(frames=("a.npy", "b.npy"), calibration="cal.h5",
                                     preprocessing=Preprocessing(crop=(0, 3, 0, 3), dead_pixels=dead),
                                     settings=Settings(iters=iters, tv_weights=(1, 2, 3))), n)

    first = stamp()
    assert stamp() == first and stamp(iters=np.int64(30)) == first  # a NumPy integer is the number it holds
    for other in (stamp(iters=31), stamp(dead=PixelMask.of(np.ones((3, 3)))), stamp(n=3)):
        assert other["fingerprint"] != first["fingerprint"]
    settings = json.loads(first["settings"])
    assert settings == json.loads(json.dumps(dataclasses.asdict(Settings(iters=30, tv_weights=(1, 2, 3)))))
    assert set(settings) == {f.name for f in dataclasses.fields(Settings)}


def test_one_spec_builds_its_solver_once_per_process_and_the_cache_is_bounded(video, tmp_path, monkeypatch):
    built, init = [], Solver.__init__

    def counting(self, *args, **kwargs):
        built.append(self)
        init(self, *args, **kwargs)

    monkeypatch.setattr(Solver, "__init__", counting)
    stream.cached_solver.cache_clear()

    def chunk(iters, start, stop):
        records = stream.solve_chunk(spec(video, iters=iters), start, stop, str(tmp_path / f"{iters}-{start}.h5"))
        assert not any(r["error"] for r in records)

    chunk(2, 0, 2)
    chunk(2, 2, 4)  # the second chunk of the same spec reuses the solver
    assert len(built) == 1
    for iters in (3, 4, 5):
        chunk(iters, 0, 1)
    assert len(built) == 4 and stream.cached_solver.cache_info().currsize == stream.SOLVERS_KEPT == 2
    chunk(2, 4, 5)  # the first spec's solver was evicted: built again
    assert len(built) == 5
