"""The benchmark tools run end to end at tiny sizes and report what their READMEs quote (no timing is asserted)."""
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import bench_iteration  # noqa: E402
import bench_recon  # noqa: E402


def test_bench_iteration_times_every_configuration_against_the_authors_and_the_fft_floor(tmp_path, capsys):
    out = tmp_path / "iteration.json"
    bench_iteration.main(["--size", "24x32", "--bands", "8", "--ranks", "2", "--backends", "numpy",
                          "--repeat", "2", "--json", str(out)])
    result = json.loads(out.read_text())
    assert set(result["seconds"]) == {"numpy full solver (--no-skip)", "numpy default (automatic rank)",
                                      "numpy support field, 8 bands", "numpy subspace r = 2", bench_iteration.AUTHORS}
    assert all(len(samples) == 2 and min(samples) > 0 for samples in result["samples"].values())
    assert result["fields"]["numpy full solver (--no-skip)"] == [48, 64]
    assert set(result["fft_floor"]) == {bench_iteration.PAPER, bench_iteration.OWN}
    table = capsys.readouterr().out
    assert table.count("\n| numpy") == 4 and "FFT floor, paper field" in table


def test_bench_recon_writes_its_tables_curves_and_plot(tmp_path, capsys):
    bench_recon.main(["--scenes", "leds", "--size", "24x32", "--bands", "8", "--iters", "20", "--authors-iters", "20",
                      "--reference-iters", "30", "--configs", "numpy,numpy --no-skip", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "results.json").read_text())["leds"]
    assert set(results) == {"numpy", "numpy --no-skip", bench_recon.AUTHORS}
    curve = results["numpy"]["curve"]
    assert [p["iteration"] for p in curve] == bench_recon.marks(20)
    assert all(b["seconds"] > a["seconds"] for a, b in zip(curve, curve[1:]))
    assert (tmp_path / "error_vs_time.png").stat().st_size > 0
    text = capsys.readouterr().out
    assert "| leds | numpy |" in text and "| leds | authors |" in text and "within 0.2 dB" in text


@pytest.mark.opencl
def test_bench_kernels_runs_every_row_on_opencl_and_numpy(tmp_path):
    pytest.importorskip("pyopencl")
    import bench_kernels

    out = tmp_path / "kernels.json"
    bench_kernels.main(["--size", "16x24", "--bands", "4", "--repeat", "1", "--json", str(out)])
    results = json.loads(out.read_text())["results"]
    assert set(results) == {"opencl", "numpy"}
    assert {"forward", "adjoint_step", "iteration"} <= set(results["opencl"]) == set(results["numpy"])
