"""The benchmark tools run end to end at tiny sizes and report what their READMEs quote (no timing is asserted)."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import opencl_device

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import admm_acceleration  # noqa: E402
import admm_duals  # noqa: E402
import bench_accuracy  # noqa: E402
import bench_admm  # noqa: E402
import bench_admm_passes  # noqa: E402
import bench_answer  # noqa: E402
import bench_breakdown  # noqa: E402
import bench_converged  # noqa: E402
import bench_iteration  # noqa: E402
import bench_panel  # noqa: E402
import bench_recon  # noqa: E402
import bench_road  # noqa: E402
import bench_stop  # noqa: E402
import compare_recon  # noqa: E402
import compare_speed  # noqa: E402
import lit_weights  # noqa: E402
import rank_signals  # noqa: E402
import weight_factors  # noqa: E402
import weight_oracles  # noqa: E402
import weight_rejudge  # noqa: E402
from clsdcam.metrics import psnr, spectral_angle  # noqa: E402
from clsdcam.solve.auto_weights import AUTO_AT, RECOUNT_AT, sparse_in_good_light  # noqa: E402
from clsdcam.solve.convergence import FIRST_READING, WINDOW  # noqa: E402
from clsdcam.algorithms.admm import Admm  # noqa: E402
from clsdcam.solve import settings  # noqa: E402
from clsdcam.solve.settings import AUTO_CAP, CONVERGE, CONVERGE_WIDE  # noqa: E402
from clsdcam.solve.priors import TotalVariation  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402


def test_bench_iteration_times_every_configuration_against_the_authors_and_the_fft_floor(tmp_path, capsys):
    out = tmp_path / "iteration.json"
    bench_iteration.main(["--size", "24x32", "--bands", "8", "--ranks", "2", "--backends", "numpy",
                          "--repeat", "2", "--json", str(out)])
    result = json.loads(out.read_text())
    assert set(result["seconds"]) == {"numpy full solver (--no-skip)", "numpy --subspace --support-field (automatic rank)",
                                      "numpy default (paper field, 8 bands)", "numpy --support-field (8 bands)",
                                      "numpy subspace r = 2", "numpy --algorithm admm (paper field, 8 bands)",
                                      bench_iteration.AUTHORS}
    assert all(len(samples) == 2 and min(samples) > 0 for samples in result["samples"].values())
    assert result["fields"]["numpy full solver (--no-skip)"] == [48, 64]
    assert set(result["fft_floor"]) == {bench_iteration.PAPER, bench_iteration.OWN}
    table = capsys.readouterr().out
    assert table.count("\n| numpy") == 6 and "FFT floor, paper field" in table


def test_bench_recon_writes_its_tables_curves_and_plot(tmp_path, capsys):
    bench_recon.main(["--scenes", "leds", "--size", "24x32", "--bands", "8", "--iters", "20", "--authors-iters", "20",
                      "--reference-iters", "30", "--configs", "numpy,numpy --no-skip,numpy --rank 2", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "results.json").read_text())["leds"]
    assert set(results) == {"numpy", "numpy --no-skip", "numpy --rank 2", bench_recon.AUTHORS}
    assert results["numpy --rank 2"]["ranks"][-1] == 2
    curve = results["numpy"]["curve"]
    assert [p["iteration"] for p in curve] == bench_recon.marks(20)
    assert all(b["seconds"] > a["seconds"] for a, b in zip(curve, curve[1:]))
    assert (tmp_path / "error_vs_time.png").stat().st_size > 0
    text = capsys.readouterr().out
    assert "| leds | numpy |" in text and "| leds | authors |" in text and "within 0.2 dB" in text


def test_bench_recon_can_time_a_few_published_iterations_and_replay_the_rest(tmp_path, capsys):
    bench_recon.main(["--scenes", "leds,target", "--size", "24x32", "--bands", "8", "--iters", "10", "--authors-iters", "25",
                      "--authors-timed", "4", "--reference-iters", "0", "--configs", "numpy", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "results.json").read_text())
    for scene in ("leds", "target"):
        authors = results[scene][bench_recon.AUTHORS]
        assert authors["timed_iterations"] == 4 and [p["iteration"] for p in authors["timed_curve"]] == [1, 4]
        assert 0 < authors["replay_difference"] < 1e-5          # float32 against float64 after four iterations
        assert [p["iteration"] for p in authors["curve"]] == bench_recon.marks(25)
        assert authors["curve"][-1]["seconds"] == pytest.approx(authors["setup"] + 25 * authors["per_iteration"])
        assert authors["curve"][-1]["error"] is None
    assert "| leds | numpy |" in capsys.readouterr().out


def test_bench_recon_times_a_single_published_iteration_from_their_set_up(tmp_path):
    bench_recon.main(["--scenes", "leds", "--size", "24x32", "--bands", "8", "--iters", "5", "--authors-iters", "1",
                      "--reference-iters", "0", "--configs", "numpy", "--out", str(tmp_path)])
    authors = json.loads((tmp_path / "results.json").read_text())["leds"][bench_recon.AUTHORS]
    assert authors["per_iteration"] == pytest.approx(authors["curve"][0]["seconds"] - authors["setup"])


@pytest.mark.parametrize("timed", ["1", "25"])
def test_bench_recon_refuses_a_timed_count_it_cannot_replay_from(tmp_path, timed):
    with pytest.raises(SystemExit) as stop:
        bench_recon.main(["--scenes", "leds", "--size", "24x32", "--bands", "8", "--authors-iters", "25",
                          "--authors-timed", timed, "--out", str(tmp_path / "out")])
    assert stop.value.code == 2 and not (tmp_path / "out").exists()


def test_bench_accuracy_compares_the_default_with_the_full_solver_the_sweep_and_fixed_ranks(tmp_path, capsys):
    bench_accuracy.main(["--scenes", "target,lines", "--size", "24x32", "--bands", "8", "--marks", "5,20",
                         "--sweep", "1e-4,1e-3", "--ranks", "2", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "accuracy.json").read_text())["scenes"]
    assert set(results["lines"]) == {"default", "--no-skip", "--tv 0.0001", "--tv 0.001", "--rank 2"}
    assert [p["iteration"] for p in results["target"]["default"]["points"]] == [5, 20]
    assert results["target"]["--tv 0.001"]["tv_chosen"] == 1e-3
    assert results["target"]["--rank 2"]["final_rank"] == 2 and results["target"]["--no-skip"]["final_rank"] == 8
    text = (tmp_path / "accuracy.md").read_text()
    assert text == capsys.readouterr().out
    main, sweep, ranks = text.split("\n\n`--tv auto`")[0], *text.split("\n\n")[2:5:2]
    assert len([line for line in main.splitlines() if line.startswith("| target |")]) == 5     # every run
    best = max(results["target"][f"--tv {tv}"]["points"][-1]["psnr"] for tv in ("0.0001", "0.001"))
    sweep_row = next(line for line in sweep.splitlines() if line.startswith("| target |"))
    assert f"{results['target']['default']['points'][-1]['psnr'] - best:+.2f} dB" in sweep_row
    rank_rows = [line for line in ranks.splitlines() if line.startswith("| target |")]
    assert rank_rows[0].startswith("| target | default |") and rank_rows[-1].startswith("| target | --rank 2 | 2 |")
    assert len(rank_rows) == 3                              # the automatic rule, the full solver, the fixed rank
    alone = {"scenes": {"target": {name: results["target"][name] for name in ("default", "--no-skip")}}}
    assert bench_accuracy.markdown(alone, [5, 20]).count("\n") == 3      # no sweep or rank table without their runs


def test_bench_accuracy_runs_another_algorithm_on_the_scenes_and_the_hand(tmp_path, shared_data):
    """``--algorithms admm``: a run of its own on every scene and on the hand (correlated with the reference)."""
    shared_data(bench_accuracy.HAND[1])
    bench_accuracy.main(["--scenes", "target", "--size", "24x32", "--bands", "8", "--marks", "3", "--algorithms",
                         "admm", "--hand", "--hand-reference-iters", "3", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "accuracy.json").read_text())
    assert set(results["scenes"]["target"]) == {"default", "--no-skip", "--algorithm admm"}
    (point,) = results["hand"]["runs"]["--algorithm admm"]["points"]
    assert point["iteration"] == 3 and 0 < point["correlation"] <= 1
    assert (tmp_path / "hand_admm.png").exists()


def test_rank_signals_reads_the_default_band_iterate_and_its_largest_gaps(tmp_path, capsys):
    rank_signals.main(["--scenes", "leds,target", "--size", "24x32", "--bands", "16", "--at", "20,40",
                       "--out", str(tmp_path)])
    results = json.loads((tmp_path / "rank_signals.json").read_text())["scenes"]
    assert (tmp_path / "rank_signals.md").read_text() == capsys.readouterr().out
    assert results["leds"]["truth"]["rule_rank"] == 3 and results["leds"]["truth"]["gaps"][0][0] == 3   # three LEDs
    for run in results.values():
        assert run["final_rank"] == 16 and list(run["iterates"]) == ["20", "40"]       # band space throughout
        for signal in run["iterates"].values():
            energies = np.array(signal["energies"])
            assert len(energies) == 9 and np.all(np.diff(energies) <= 0) and energies.sum() <= 1 + 1e-12
            ratios = energies[:-1] / energies[1:]
            assert [j for j, _ in signal["gaps"]] == list(np.argsort(ratios)[::-1][:2] + 1)
            assert [ratio for _, ratio in signal["gaps"]] == pytest.approx(np.sort(ratios)[::-1][:2])
    sim = rank_signals.simulate(scene="target", shape=(24, 32), n_bands=16, seed=0)   # still warming up at 40
    default = rank_signals.Solver(sim.calibration, settings=rank_signals.Settings(iters=40))
    cube = default.solve(sim.measurement, snapshots=[40]).snapshots[40]
    assert rank_signals.signals(cube) == results["target"]["iterates"]["40"]


def test_rank_signals_counts_round_off_as_zero_and_needs_two_eigenvalues_per_gap():
    rotation = np.linalg.qr(np.random.default_rng(1).standard_normal((8, 8)))[0]
    spectra = rotation[:, [0] * 5 + [1] * 3 + [2] * 2]       # three orthonormal spectra on 5, 3 and 2 pixels
    signal = rank_signals.signals(spectra.reshape(8, 2, 5))
    assert signal["rule_rank"] == 3
    assert signal["gaps"][0][0] == 3 and signal["gaps"][0][1] > 1e10           # e_4… are round-off: zero
    assert signal["gaps"][1] == [1, pytest.approx(0.5 / 0.3)]
    exact = rank_signals.signals(np.eye(8)[:, [0] * 5 + [1] * 3 + [2] * 2].reshape(8, 2, 5))   # e_4… exactly 0
    assert exact["gaps"][0] == [3, pytest.approx(0.2 / rank_signals.ROUND_OFF)]
    assert rank_signals.signals(spectra[:, :5].reshape(8, 1, 5))["gaps"] == [[1, pytest.approx(1e12)]]  # one spectrum
    assert rank_signals.signals(np.zeros((8, 2, 5)))["gaps"] == []
    assert len(rank_signals.signals(spectra[:2].reshape(2, 2, 5))["gaps"]) == 1


@pytest.mark.opencl
def test_bench_kernels_runs_every_row_on_opencl_and_numpy(tmp_path):
    opencl_device()
    import bench_kernels

    out = tmp_path / "kernels.json"
    bench_kernels.main(["--size", "16x24", "--bands", "4", "--repeat", "1", "--json", str(out)])
    results = json.loads(out.read_text())["results"]
    assert set(results) == {"opencl", "numpy"}
    assert {"forward", "adjoint_step", "iteration"} <= set(results["opencl"]) == set(results["numpy"])


@pytest.mark.opencl
def test_check_vkfft_plans_counts_wrong_plans_per_shape(capsys):
    pytest.importorskip("pyvkfft")
    opencl_device()
    import check_vkfft_plans

    check_vkfft_plans.main(["--shapes", "2x21x35,1x8x47", "--plans", "2"])
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("| ") and "shape" not in line]
    assert rows[0] == "| 2x21x35 | no, no | 0 of 2 |"                 # 7-smooth: VkFFT's own radices, right
    assert rows[1].startswith("| 1x8x47 | yes, no |")               # 47: Bluestein's algorithm on the W axis


def test_bench_panel_draws_fresh_scenes_of_every_kind_and_judges_both_rules(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    bench_panel.main(["--size", "24x32", "--bands", "8", "--scenes", "5", "--marks", "4,8", "--sweep", "3",
                      "--seed", "7", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "panel.json").read_text())
    assert results["seed"] == 7 and [s["kind"] for s in results["scenes"]] == ["piecewise", "natural", "sparse",
                                                                              "lines", "piecewise"]
    assert [s["level"] for s in results["scenes"]] == ["standard"] * 4 + ["low light"]
    for scene in results["scenes"]:
        chosen = scene["runs"]["default"]["tv_chosen"]
        fixed = sorted(run["tv_chosen"] for name, run in scene["runs"].items() if name.startswith("--tv "))
        assert fixed == pytest.approx([chosen / 10, chosen, chosen * 10])
        assert [p["iteration"] for p in scene["runs"]["--no-skip"]["points"]] == [4, 8]
        assert {run["algorithm"] for run in scene["runs"].values()} == {"fista"}   # fixed marks: today's default's
    text = capsys.readouterr().out
    assert text.count("| piecewise | 2 |") == 2 and "| sparse | 1 |" in text and text == (tmp_path / "panel.md").read_text()
    margins = [bench_panel.rule_margins(s)[0] for s in results["scenes"]]
    worst = f"{min(m for s, m in zip(results['scenes'], margins) if s['kind'] == 'piecewise'):+.2f}"
    assert f"| piecewise | 2 | {worst} / " in text
    assert bench_panel.scene_plan(5, 7) == bench_panel.scene_plan(5, 7) != bench_panel.scene_plan(5, 8)
    assert [title for title, _ in bench_panel.margin_panels(results)] == [
        "default against --no-skip, worst mark", "chosen weight against the best fixed weight"]
    assert (tmp_path / "panel.png").stat().st_size > 0 and (tmp_path / "curves.png").stat().st_size > 0


def test_bench_converged_judges_the_three_rules_against_cached_references(tmp_path, capsys, monkeypatch):
    """Each scene: today, the default and both references; the answer is the better reference final per metric, the
    margins follow from the finals; a replay reads the references from the cache (no new file) and gives the same
    reference; the stop replayed at a huge tolerance stops where the estimate is first read (FIRST_READING after the
    weight's restart), and so does the default run at that tolerance (--converge)."""
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    monkeypatch.setattr(bench_panel, "panel_kinds", lambda: ["piecewise", "sparse"])
    args = ["--size", "24x32", "--bands", "4", "--scenes", "2", "--seed", "3", "--reference-iters", "200",
            "--replay", "1e9", "--cache", str(tmp_path / "cache"), "--out", str(tmp_path / "a")]
    bench_converged.main(args)
    first = json.loads((tmp_path / "a" / "converged.json").read_text())
    cached = sorted((tmp_path / "cache").iterdir())
    assert len(cached) == 4 and [s["kind"] for s in first["scenes"]] == ["piecewise", "sparse"]
    for scene in first["scenes"]:
        finals = [run["points"][-1] for run in scene["references"].values()]
        assert scene["reference"] == {"psnr": max(p["psnr"] for p in finals), "angle": min(p["angle"] for p in finals)}
        assert scene["today"]["iterations"] == 300 and scene["default"]["stop_reason"] in ("converged", "iterations")
        margins = scene["margins"]
        assert margins["answer_db"] == pytest.approx(scene["default"]["psnr"] - scene["reference"]["psnr"] + 0.2)
        assert margins["time_ratio"] == pytest.approx(scene["default"]["seconds"] / scene["today"]["seconds"])
        stop = bench_converged.replay_stop(scene["references"]["admm"], 1e9)
        assert stop["iteration"] == bench_converged.AUTO_AT + FIRST_READING
    text, progress = capsys.readouterr()
    assert "| 0 | piecewise | standard |" in text and "stop at 1e+09" in text
    assert "piecewise, standard: today's 300 iterations in" in progress
    assert "sparse, standard: admm's reference, 200 iterations in" in progress
    bench_converged.main(args[:-1] + [str(tmp_path / "b"), "--converge", "1e9"])
    again = json.loads((tmp_path / "b" / "converged.json").read_text())
    assert sorted((tmp_path / "cache").iterdir()) == cached
    assert [s["reference"] for s in again["scenes"]] == [s["reference"] for s in first["scenes"]]
    text, progress = capsys.readouterr()
    assert again["converge"] == 1e9 and "the default at --converge 1e+09" in text
    assert {s["default"]["tolerance"] for s in again["scenes"]} == {1e9} and "converged at 1e+09 |" in text
    assert all(s["default"]["tolerance"] in (CONVERGE, CONVERGE_WIDE) for s in first["scenes"])
    assert all((s["default"]["tolerance"] == CONVERGE_WIDE)
               == (s["default"]["mean_over_peak"] >= Admm.point_like_below and not sparse_in_good_light(s["default"]))
               for s in first["scenes"])
    assert f"the default's {bench_converged.AUTO_AT + FIRST_READING} iterations (converged)" in progress
    assert "reference" not in progress                  # read from the cache: no solve to report
    assert [s["default"]["iterations"] for s in again["scenes"]] == [bench_converged.AUTO_AT + FIRST_READING] * 2
    assert (tmp_path / "b" / "converged.png").stat().st_size > 0
    bench_converged.main(["--against", str(tmp_path / "a"), "--only", "1", "--replay", "1e9", "--cache",
                          str(tmp_path / "none"), "--out", str(tmp_path / "c")])     # size, bands, seed: the run's
    timed = json.loads((tmp_path / "c" / "converged.json").read_text())
    assert (timed["seed"], timed["size"], timed["bands"], timed["against"]) == (3, "24x32", 4, str(tmp_path / "a"))
    assert timed["host_steps"] == first["host_steps"] == "JitSplitting"
    assert [(s["index"], s["kind"], s["references"]) for s in timed["scenes"]] == [
        (1, "sparse", first["scenes"][1]["references"])]
    assert timed["scenes"][0]["default"]["iterations"] == first["scenes"][1]["default"]["iterations"]
    assert not list((tmp_path / "none").iterdir()) and "reference" not in capsys.readouterr().err


SCENELESS = json.dumps({"seed": 3, "size": "24x32", "bands": 4, "reference_iters": 200, "kinds": None, "scenes": []})


@pytest.mark.parametrize("stored, only, said", [(None, [], "--against"), ("{}", [], "--against"),
                                                (SCENELESS, ["--only", "2"], "--only 2"),
                                                (SCENELESS, [], "holds no scenes")])
def test_bench_converged_refuses_an_earlier_run_it_cannot_use_before_writing(tmp_path, capsys, stored, only, said):
    """--against a folder with no converged.json, with one that is not a run's or holds no scenes, or --only a scene
    it does not hold: one line, exit 2, nothing written."""
    if stored is not None:
        (tmp_path / "run").mkdir()
        (tmp_path / "run" / "converged.json").write_text(stored)
    with pytest.raises(SystemExit) as exit_:
        bench_converged.main(["--against", str(tmp_path / "run"), *only, "--out", str(tmp_path / "out")])
    assert exit_.value.code == 2 and not (tmp_path / "out").exists()
    assert said in capsys.readouterr().err.splitlines()[-1]


@pytest.mark.parametrize("tolerance", ["0", "-0.1", "nan", "inf"])
def test_bench_converged_refuses_a_tolerance_that_is_not_positive_before_writing(tmp_path, tolerance):
    with pytest.raises(SystemExit) as exit_:
        bench_converged.main(["--converge", tolerance, "--out", str(tmp_path / "out")])
    assert exit_.value.code == 2 and not (tmp_path / "out").exists()


def test_panels_draw_the_simulators_point_scenes_with_kinds(tmp_path, capsys):
    """--kinds points,sources: a panel's scenes are the simulator's scenes of those names, in turn, at each scene's
    seed and noise level (the simulation is simulate's own); a kind that is none of the panel's or those is one line
    on stderr, exit 2, before a folder is made."""
    import argparse

    from clsdcam.sim import simulate

    args = argparse.Namespace(scenes=4, only=None, kinds=bench_panel.kind_list("points, sources"))
    chosen = bench_panel.chosen_scenes(None, args, 5)
    assert [plan["kind"] for _, plan in chosen] == ["points", "sources"] * 2
    assert [plan["level"] for _, plan in chosen] == ["standard", "standard", "low light", "low light"]
    for _, plan in chosen:
        sim = bench_panel.panel_scene(plan, (24, 32), 4)
        own = simulate(plan["kind"], (24, 32), 4, plan["seed"] % 2 ** 31, **bench_panel.LEVELS[plan["level"]])
        assert sim.scene == plan["kind"] and np.array_equal(sim.truth, own.truth)
        assert np.array_equal(sim.measurement, own.measurement)
    for tool in (bench_panel, bench_converged, bench_stop, bench_answer):
        with pytest.raises(SystemExit) as stop:
            tool.main(["--kinds", "points,dots", "--seed", "1", "--out", str(tmp_path / "out")])
        errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
        assert stop.value.code == 2 and len(errors) == 1 and "--kinds" in errors[0] and "sources" in errors[0]
    assert not (tmp_path / "out").exists()


ONE_PIECEWISE_SCENE = ["--size", "24x32", "--bands", "4", "--scenes", "1", "--seed", "3", "--reference-iters", "150"]


@pytest.fixture
def piecewise_panel(monkeypatch):
    """bench_converged's panel drawn from the piecewise kind alone (no real cube needed)."""
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    monkeypatch.setattr(bench_panel, "panel_kinds", lambda: ["piecewise"])


def test_bench_converged_measures_admm_variants_and_restores_the_constants(tmp_path, capsys, piecewise_panel):
    """``--variants``: each variant runs with its constants (α = 1 and 1.7 give other curves), the settled mark is
    the first from which every mark is within, a huge tolerance stops where the estimate is first read, and the
    modules' constants are as before afterwards."""
    from clsdcam.algorithms.admm import algorithm, balance

    constants = lambda: (algorithm.RELAXATION, algorithm.TV, algorithm.BALANCE_AT, balance.THRESHOLD_OVER_RMS,
                         balance.THRESHOLD_FEW_POINTS, balance.THRESHOLD_POINT_LIKE, algorithm.NONNEG_POINT_LIKE)
    before = constants()
    changed = {"few_balance": 5.0, "balance": 3.0, "point_balance": 4.0, "nonneg_point": 1e-3}
    with bench_converged.admm_constants(changed):
        assert (balance.THRESHOLD_FEW_POINTS, balance.THRESHOLD_OVER_RMS) == (5.0, 3.0)
        assert (balance.THRESHOLD_POINT_LIKE, algorithm.NONNEG_POINT_LIKE) == (4.0, 1e-3)
    assert constants() == before
    bench_converged.main([*ONE_PIECEWISE_SCENE, "--variants",
                          "alpha=1,balance_at=1e9;alpha=1.7,tv=0.003,balance=3,balance_at=40",
                          "--variant-iters", "200", "--replay", "1e9", "--cache", str(tmp_path / "cache"),
                          "--out", str(tmp_path)])
    assert constants() == before
    scene = json.loads((tmp_path / "variants.json").read_text())["scenes"][0]
    plain, relaxed = scene["variants"]
    assert plain["variant"] == {"alpha": 1.0, "balance_at": 1e9} and plain["balance"] is None
    assert relaxed["variant"] == {"alpha": 1.7, "tv": 0.003, "balance": 3.0, "balance_at": 40.0}
    assert len(relaxed["balance"]) == 3 and all(b > 0 for b in relaxed["balance"])
    first_stops = [stop["iteration"] for stop in (plain["stops"][0], relaxed["stops"][0])]
    assert first_stops == [bench_converged.AUTO_AT + FIRST_READING] * 2
    points = [{"iteration": 10, "psnr": 0.0, "angle": 0.0}, {"iteration": 20, "psnr": 9.0, "angle": 0.0},
              {"iteration": 30, "psnr": 0.0, "angle": 0.0}, {"iteration": 40, "psnr": 9.0, "angle": 1.0}]
    assert bench_converged.settled_within(points, {"psnr": 9.1, "angle": 0.6}) == 40
    assert bench_converged.settled_within(points, {"psnr": 9.1, "angle": 0.0}) is None
    out = capsys.readouterr().out
    assert "| 0 | piecewise, standard | alpha 1.7, tv 0.003, balance 3, balance_at 40 |" in out
    assert "| 0 | piecewise, standard | alpha 1, balance_at 1e+09 | 0 |" in out


def test_told_point_like_gives_admm_the_probes_penalties_before_the_balance_and_restores_the_method(monkeypatch):
    """A solve at a given weight reads no probe: told, ADMM's μ₃ falls to NONNEG_POINT_LIKE/NONNEG of its value after
    AUTO_AT iterations, as the default's does on a point-like scene, and told a few points to NONNEG_FEW_POINTS/NONNEG,
    its TV balance at that iteration taking the point-like scenes' wider thresholds, or the few points' wider still;
    told a few points in good light and not of the fewest (``lighter``), it takes the point-like scene's penalties, and
    where told the recount ``rerouted``, after RECOUNT_AT iterations the few points' with μ₁ and μ₃ LIGHTER_FEW_POINTS
    of those, the TV balanced again with the few points' C (``Admm.few_points_to_lighten``); told a rerouted few
    points, after RECOUNT_AT iterations μ₃ is NONNEG_POINT_LIKE of μ₂'s scale (``Admm.lit_spots``); not told, or
    before that iteration, or after the context, it keeps its penalties."""
    from clsdcam.algorithms.admm import algorithm, balance
    from clsdcam.sim import simulate

    sim = simulate(scene="points", shape=(24, 32), n_bands=4, seed=2)
    plain = Admm.iterate

    def penalties(iters: int, **told):
        settings = Settings(iters=iters, algorithm="admm", tv=1e-3)
        with bench_converged.told_point_like(**told):
            result = Solver(sim.calibration, settings=settings).solve(sim.measurement)
        return result.state.carry[0].penalties

    kept, point_like = penalties(AUTO_AT + 2), penalties(AUTO_AT + 2, point_like=True)
    few_told = {"point_like": True, "few_points": True}
    few = penalties(AUTO_AT + 2, **few_told)
    assert point_like.nonneg == pytest.approx(kept.nonneg * algorithm.NONNEG_POINT_LIKE / algorithm.NONNEG, rel=1e-12)
    assert few.nonneg == pytest.approx(kept.nonneg * algorithm.NONNEG_FEW_POINTS / algorithm.NONNEG, rel=1e-12)
    assert few.nonneg < point_like.nonneg
    wider = balance.THRESHOLD_OVER_RMS / balance.THRESHOLD_POINT_LIKE             # C = 8 against 2: lower penalties
    assert point_like.tv_balance == pytest.approx([wider * k for k in kept.tv_balance], rel=1e-9)
    assert all(f < p for f, p in zip(few.tv_balance, point_like.tv_balance))     # C = 16 against 8: lower still
    assert penalties(AUTO_AT, point_like=True).nonneg == kept.nonneg
    lighter = {"point_like": True, "few_points": True, "lighter": True}
    assert penalties(AUTO_AT + 2, **lighter) == point_like                  # told point-like until the recount
    scenes, real = [], balance.balance
    monkeypatch.setattr(balance, "balance", lambda *a: scenes.append(a[3:]) or real(*a))
    bright = penalties(RECOUNT_AT + 1, **lighter, rerouted=True)            # a few points then, lightened
    assert scenes == [("point_like",), ("few_points",)]                     # balanced again with C = 16
    assert bright.data == pytest.approx(kept.data * algorithm.LIGHTER_FEW_POINTS, rel=1e-12)
    assert bright.nonneg == pytest.approx(few.nonneg * algorithm.LIGHTER_FEW_POINTS, rel=1e-12)
    assert penalties(RECOUNT_AT + 1, **lighter) == penalties(RECOUNT_AT + 1, point_like=True)     # lit spots
    spots = penalties(RECOUNT_AT + 1, point_like=True, few_points=True, rerouted=True)
    assert spots.nonneg / spots.tv == pytest.approx(algorithm.NONNEG_POINT_LIKE / algorithm.TV, rel=1e-12)
    assert spots.data == pytest.approx(kept.data, rel=1e-12)           # the camera's
    assert spots.tv_balance is not None and spots.tv_balance != few.tv_balance      # balanced again, C = 2
    assert penalties(RECOUNT_AT, point_like=True, few_points=True, rerouted=True) == penalties(RECOUNT_AT, **few_told)
    assert Admm.iterate is plain


def test_anderson_point_is_an_affine_maps_fixed_point_after_as_many_differences_as_dimensions():
    """For T(q) = Mq + c in R³, three differences span the space: the Anderson point is the fixed point (I − M)⁻¹c,
    which the plain iterates are still far from; with no difference it is the newest map."""
    rng = np.random.default_rng(5)
    m, c = 0.9 * np.linalg.qr(rng.normal(size=(3, 3)))[0], rng.normal(size=3)
    q, maps, residuals = rng.normal(size=3), [], []
    for _ in range(4):
        g = m @ q + c
        maps.append([g])
        residuals.append([g - q])
        q = g
    fixed = np.linalg.solve(np.eye(3) - m, c)
    dot = lambda a, b: float(np.vdot(a[0], b[0]))
    assert np.linalg.norm(q - fixed) > 0.1
    point = admm_acceleration.anderson_point(maps, residuals, dot)[0]
    np.testing.assert_allclose(point, fixed, rtol=1e-6)        # the ridge's 1e-10·trace, magnified by the fit
    assert admm_acceleration.anderson_point(maps[:1], residuals[:1], dot)[0] is maps[0][0]


def test_the_split_inputs_give_back_the_state_the_splits_left(monkeypatch):
    """Writing the splits' inputs read from the state after the splits gives back that state, at every iteration of a
    solve with all three splits and over-relaxation: every array, and x − ξ over the field, which the host keeps as
    Ŷ and the window's change in ``hv`` (set again, all of it in Ŷ)."""
    from clsdcam.algorithms.admm.terms import SplittingBase

    plain, checked = SplittingBase.iterate, []

    def data_input(split, state):
        h, w = split.sensor_shape
        field = split.data_split(state)
        field[:, :h, :w] -= state.xi
        return field

    def iterate(split, state):
        result = plain(split, state)
        before = {n: getattr(state, n).copy() for n in admm_acceleration.LINEAR_IN_SPLITS}
        before["x − ξ"] = data_input(split, state)
        admm_acceleration.set_split_inputs(split, state, admm_acceleration.split_inputs(split, state))
        after = {n: getattr(state, n) for n in admm_acceleration.LINEAR_IN_SPLITS} | {"x − ξ": data_input(split, state)}
        for name in set(before) - {"hv", "data_spectrum"}:
            array = before[name]
            np.testing.assert_allclose(after[name], array, rtol=1e-5, atol=1e-6 * np.abs(array).max(), err_msg=name)
        checked.append(True)
        return result

    monkeypatch.setattr(SplittingBase, "iterate", iterate)
    plan = bench_panel.scene_plan(1, 3, ["piecewise"])[0]
    sim = bench_panel.panel_scene(plan, (24, 32), 4)
    bench_converged.timed_solve(sim, {"tv": 1e-3, "iters": 12, "algorithm": "admm"})
    assert len(checked) == 12


def test_spectral_estimate_reads_a_linear_pairs_slope_and_refuses_a_non_monotone_one():
    """Δλ = cΔx: both spectral estimates are c, the correlation 1; Δλ = −Δx is not monotone; the penalty takes the
    geometric mean of two usable estimates, the one usable, or stays."""
    step = np.random.default_rng(2).normal(size=50)
    estimate, correlation = admm_acceleration.spectral_estimate(step, 3.0 * step)
    assert estimate == pytest.approx(3.0) and correlation == pytest.approx(1.0)
    assert admm_acceleration.spectral_estimate(step, -step) == (None, 0.0)
    assert admm_acceleration.spectral_penalty(1.0, (4.0, 0.9), (9.0, 0.5)) == pytest.approx(6.0)
    assert admm_acceleration.spectral_penalty(1.0, (4.0, 0.1), (9.0, 0.5)) == 9.0
    assert admm_acceleration.spectral_penalty(1.0, (None, 0.0), (9.0, 0.1)) == 1.0


def test_a_penalty_change_keeps_the_splits_and_the_unscaled_duals(monkeypatch):
    """After new penalties the splits z and the unscaled duals μy are as before (a fixed point stays one)."""
    from clsdcam.algorithms.admm.terms import Penalties, SplittingBase

    plain, checked = SplittingBase.iterate, []

    def iterate(split, state):
        result = plain(split, state)
        p = split.penalties
        z, y = admm_acceleration.split_variables(split, state)
        new = Penalties(2 * p.data, 0.5 * p.tv, 3 * p.nonneg)
        admm_acceleration.change_penalties(split, state, new)
        z2, y2 = admm_acceleration.split_variables(split, state)
        for before, after, ratio in zip(y, y2, (2, 0.5, 3)):
            np.testing.assert_allclose(ratio * after, before, rtol=1e-5, atol=1e-6 * (np.abs(before).max() + 1))
        for before, after in zip(z, z2):
            np.testing.assert_allclose(after, before, rtol=1e-5, atol=1e-6 * (np.abs(before).max() + 1))
        checked.append(split.penalties is new)
        return result

    monkeypatch.setattr(SplittingBase, "iterate", iterate)
    plan = bench_panel.scene_plan(1, 3, ["piecewise"])[0]
    bench_converged.timed_solve(bench_panel.panel_scene(plan, (24, 32), 4), {"tv": 1e-3, "iters": 6,
                                                                              "algorithm": "admm"})
    assert checked == [True] * 6


def test_the_fixed_point_data_dual_is_the_one_admm_converges_to(monkeypatch):
    """ξ set from the iterate w by its fixed-point value, −f·(b − fᵀHw)/μ₁, is what ADMM's own ξ approaches as the
    solve converges (relative distance 2.0 after 200 iterations, 0.04 after 3000 on this scene); the splits it
    leaves are w's (x = Hw) and the c-step's right-hand side x − ξ."""
    import copy

    from clsdcam.algorithms.admm.terms import SplittingBase

    plain, last = SplittingBase.iterate, {}

    def iterate(split, state):
        last["split"], last["state"] = split, state
        return plain(split, state)

    def distance(iters: int) -> float:
        bench_converged.timed_solve(sim, {"tv": 1e-3, "iters": iters, "algorithm": "admm"})
        split, state = last["split"], last["state"]
        derived = copy.deepcopy(state)
        admm_duals.fixed_point_duals(split, derived, state.w.copy(), admm_duals.XI_ALONE)
        h, w = split.sensor_shape
        hw = split.convolve(np.maximum(state.w, 0))

        def near(a, b):            # through a float32 transform and back: relative L2 within 10⁻⁵
            return np.linalg.norm(a - b) <= 1e-5 * np.linalg.norm(b)

        np.testing.assert_allclose(derived.x, hw[:, :h, :w], rtol=1e-4, atol=1e-6)
        assert near(split.data_split(derived), hw)
        hw[:, :h, :w] -= derived.xi                                   # x − ξ, the c-step's: Ŷ, nothing left in hv
        assert near(np.fft.irfft2(derived.data_spectrum, s=split.field_shape), hw) and not derived.hv.any()
        return float(np.linalg.norm(derived.xi - state.xi) / np.linalg.norm(state.xi))

    monkeypatch.setattr(SplittingBase, "iterate", iterate)
    plan = bench_panel.scene_plan(1, 3, ["piecewise"])[0]
    sim = bench_panel.panel_scene(plan, (24, 32), 4)
    early, late = distance(200), distance(3000)
    assert late < 0.1 and late < early / 10


def test_bench_converged_measures_the_duals_variants_and_restores_the_solver(tmp_path, piecewise_panel):
    """``duals`` on a start, ``refresh`` and ``rebalance`` run, each counted once; a second balance sets other β_d
    than the one balance; the host start and ADMM's iteration are as before after; on OpenCL they are refused."""
    from clsdcam.algorithms.admm.host_steps import Splitting

    start, iterate = Splitting.start, Admm.iterate
    bench_converged.main([*ONE_PIECEWISE_SCENE, "--variants", "balance_at=30;answer_start=150,duals=2;refresh=35;"
                          "rebalance=45", "--variant-iters", "60", "--replay", "1e9", "--cache",
                          str(tmp_path / "cache"), "--out", str(tmp_path)])
    assert (Splitting.start, Admm.iterate) == (start, iterate)
    plain, *varied = json.loads((tmp_path / "variants.json").read_text())["scenes"][0]["variants"]
    assert plain["restarts"] == 0 and [v["restarts"] for v in varied] == [1, 1, 1]
    assert varied[1]["final"] != plain["final"]
    assert varied[2]["balance"] != plain["balance"] and varied[1]["balance"] == plain["balance"]
    with pytest.raises(SystemExit) as refused:
        bench_converged.main([*ONE_PIECEWISE_SCENE, "--variants", "duals=1", "--backend", "opencl",
                              "--out", str(tmp_path / "no")])
    assert refused.value.code == 2 and not (tmp_path / "no").exists()


def test_bench_converged_measures_the_accelerations_and_restores_the_iteration(tmp_path, capsys, piecewise_panel):
    """``momentum``, ``anderson`` and ``spectral`` variants run other curves than the plain ADMM, count their
    restarts (penalty changes), and leave the host iteration as it was; on OpenCL they are refused."""
    from clsdcam.algorithms.admm.terms import SplittingBase

    plain = SplittingBase.iterate
    args = [*ONE_PIECEWISE_SCENE,
            "--variants", "alpha=1.7;alpha=1.7,momentum=0.999;alpha=1.7,anderson=3;alpha=1.7,spectral=2",
            "--variant-iters", "60", "--replay", "1e9", "--cache", str(tmp_path / "cache"), "--out", str(tmp_path)]
    bench_converged.main(args)
    assert SplittingBase.iterate is plain
    rows = json.loads((tmp_path / "variants.json").read_text())["scenes"][0]["variants"]
    assert rows[0]["restarts"] == 0 and rows[1]["restarts"] > 0 and isinstance(rows[2]["restarts"], int)
    assert rows[3]["restarts"] > 0
    finals = [r["final"]["psnr"] for r in rows]
    assert len(set(finals)) == 4
    assert "| 0 | piecewise, standard | alpha 1.7, anderson 3 |" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        bench_converged.main(args + ["--backend", "opencl"])
    assert "wrap the host steps" in capsys.readouterr().err


def test_fast_admm_measures_its_residual_from_the_point_it_extrapolated(monkeypatch):
    """The momentum variant's combined residual compares the splits after the iteration with the splits and duals it
    started from (ẑ, ŷ: the extrapolated point), read before the c-step, which relaxes the host's x − ξ in place."""
    from clsdcam.algorithms.admm.terms import SplittingBase

    plain, checked, momentum = SplittingBase.iterate, [], admm_acceleration.Momentum(0.999, {"restarts": 0})
    measured = admm_acceleration.Momentum.combined_residual

    def iterate(split, state):
        start = admm_acceleration.split_variables(split, state)

        def residual(split_, now, hat):
            for before, read in zip(start[0] + start[1], hat[0] + hat[1]):
                assert (before is None and read is None) or np.array_equal(before, read)
            checked.append(True)
            return measured(split_, now, hat)

        monkeypatch.setattr(momentum, "combined_residual", residual)
        return momentum(split, plain, state)

    monkeypatch.setattr(SplittingBase, "iterate", iterate)
    plan = bench_panel.scene_plan(1, 3, ["piecewise"])[0]
    bench_converged.timed_solve(bench_panel.panel_scene(plan, (24, 32), 4), {"tv": 1e-3, "iters": 5,
                                                                              "algorithm": "admm"})
    assert len(checked) == 5


def test_bench_converged_measures_starts_from_fista_and_from_the_answer(tmp_path, capsys, piecewise_panel):
    """``fista_start`` and ``answer_start`` run ADMM from their cubes (other curves than the zero start's) and count
    what the start took; the answer's start, as many ADMM iterations as the reference, ends nearer the reference's
    PSNR than the zero start does in as few iterations."""
    bench_converged.main([*ONE_PIECEWISE_SCENE,
                          "--variants", "alpha=1.7;alpha=1.7,fista_start=20;alpha=1.7,answer_start=150",
                          "--variant-iters", "20", "--replay", "1e9", "--cache", str(tmp_path / "cache"),
                          "--out", str(tmp_path)])
    scene = json.loads((tmp_path / "variants.json").read_text())["scenes"][0]
    zero, fista, answer = scene["variants"]
    assert zero["start_iterations"] == 0 and fista["start_iterations"] > 0 and answer["start_iterations"] > 0
    assert len({v["final"]["psnr"] for v in scene["variants"]}) == 3
    target = scene["reference"]["psnr"]
    assert abs(answer["final"]["psnr"] - target) < abs(zero["final"]["psnr"] - target)
    assert "| 0 | piecewise, standard | alpha 1.7, answer_start 150 |" in capsys.readouterr().out


def test_bench_stop_traces_the_true_distance_and_both_estimates(tmp_path, capsys, piecewise_panel):
    """The traced run of as many iterations as the reference is the reference: its last cube is at distance 0; at a
    huge tolerance the steps' estimate fires at FIRST_READING (three ratios, then three finite tails) and the net
    one a window later (its first window starts at iteration 25); a stop's distance is its mark's; "stays within"
    reads every later mark; the reference's own error is its cube's relative distance from the truth."""
    bench_stop.main([*ONE_PIECEWISE_SCENE, "--reference-iters", "200", "--iters", "200", "--tolerances", "1e9",
                     "--cache", str(tmp_path / "cache"), "--out", str(tmp_path)])
    scene = json.loads((tmp_path / "stop.json").read_text())["scenes"][0]
    marks = scene["marks"]
    assert [m["iteration"] for m in marks] == list(range(5, 201, 5)) and marks[-1]["distance"] == 0.0
    assert marks[0]["distance"] > 0.05
    sim = bench_panel.panel_scene({k: scene[k] for k in ("kind", "level", "seed")}, (24, 32), 4)
    xstar = bench_converged.reference_cube(sim, scene, scene["tv"], "admm", 200, tmp_path / "cache").astype(np.float64)
    assert scene["error"] == pytest.approx(np.linalg.norm(sim.truth - xstar) / np.linalg.norm(xstar), rel=1e-9)
    assert 0.01 < scene["error"] < 10
    (steps,), (net,) = scene["stops"]["steps"], scene["stops"]["net"]
    assert (steps["iteration"], net["iteration"]) == (FIRST_READING, FIRST_READING + WINDOW)
    assert steps["distance"] == marks[FIRST_READING // 5 - 1]["distance"]
    assert net["distance"] == marks[(FIRST_READING + WINDOW) // 5 - 1]["distance"]
    ref = {"psnr": 9.0, "angle": 1.0}
    flags = [{"iteration": k, "psnr": p, "angle": 0.0, "within": p >= 8.8, "steps": s}
             for k, p, s in ((5, 9.0, 9.0), (10, 0.0, 0.1), (15, 9.0, 0.01))]
    assert bench_stop.settled(flags, ref)["iteration"] == 15
    assert bench_stop.stop(flags, "steps", 0.5) == {**flags[1], "stays_within": False}
    assert "| 0 | piecewise, standard |" in capsys.readouterr().out and (tmp_path / "stop.png").stat().st_size > 0


def test_bench_road_splits_the_road_left_into_orthogonal_parts(tmp_path, capsys, piecewise_panel):
    """A difference made of one part is all that part's; the parts of any difference add up to it; an iterate on the
    answer's own road (x* plus a multiple of its error) has a cosine of 1 with it; a mark as long as the reference
    is the answer (distance 0, no road to share out); the shares of a mark short of it add up to 1; the light in its
    window is the answer's, and the margin holds some."""
    rng = np.random.default_rng(0)
    truth = rng.random((4, 64, 64)) + 1
    flat = np.broadcast_to(np.ones((64, 64)), truth.shape)
    spectra = np.broadcast_to(np.array([1.0, -1.0, 2.0, -2.0])[:, None, None], truth.shape) * rng.random((64, 64))
    for e, part in ((0.1 * flat, "smooth achromatic"), (0.1 * spectra, "chromatic")):
        assert bench_road.anatomy(truth + 0.2 + e, truth + 0.2, truth)["energy"][part] == pytest.approx(1)
    e = rng.random(truth.shape)
    assert sum(bench_road.parts(e).values()) == pytest.approx(e)
    road = bench_road.anatomy(truth + 0.3 * flat, truth + 0.2 * flat, truth)
    assert road["cosine"] == pytest.approx(1) and road["gap"]["smooth achromatic"] == pytest.approx(1)
    assert road["psnr_gap"] == pytest.approx(psnr(truth + 0.2 * flat, truth) - psnr(truth + 0.3 * flat, truth))
    bench_road.main([*ONE_PIECEWISE_SCENE, "--reference-iters", "200", "--marks", "40,200",
                     "--cache", str(tmp_path / "cache"), "--out", str(tmp_path)])
    scene = json.loads((tmp_path / "road.json").read_text())["scenes"][0]
    first, last = scene["marks"]
    assert first["distance"] > 0.01 and last["distance"] == 0.0 and last["psnr_gap"] == 0.0
    assert all(np.isnan(share) for share in last["energy"].values()) and np.isnan(last["cosine"])
    assert sum(first["energy"].values()) == pytest.approx(1) and sum(first["gap"].values()) == pytest.approx(1)
    assert sum(last["light"].values()) > last["light"]["window"] > 0
    assert scene["answer_light"] == pytest.approx(last["light"]["window"], rel=1e-5)
    assert "| 0 | piecewise, standard | 40 |" in capsys.readouterr().out


def test_bench_answer_replays_the_default_stop_where_the_default_stops(tmp_path, capsys, monkeypatch):
    """On a two-scene panel at 32×40×8, with the cap at 830 (a window's end): a two-point scene, point-like with a
    few lit voxels, whose narrowed stop runs to the cap, and a sixteen-source scene, not point-like at this size,
    whose widened stop converges before it. On each the replayed stop at the default's own tolerance ends where a
    default solve of the scene ends, with its cube's PSNR (and the probe's noise); the answer is the last mark;
    "needs" is the widest grid tolerance whose stop is within; the cap ends a stop whose estimate falls only after
    it; a trajectory too short to read the drift is refused."""
    for module in (settings, bench_answer):
        monkeypatch.setattr(module, "AUTO_CAP", 830)
    args = ["--size", "32x40", "--bands", "8", "--scenes", "2", "--kinds", "points,sources", "--seed", "5",
            "--iters", "1100", "--tolerances", "1e9", "--out", str(tmp_path)]
    bench_answer.main(args)
    results = json.loads((tmp_path / "answer.json").read_text())
    assert [(s["point_like"], s["default"]["converged"]) for s in results["scenes"]] == [(True, False), (False, True)]
    for scene in results["scenes"]:
        sim = bench_panel.panel_scene({k: scene[k] for k in ("kind", "level", "seed")}, (32, 40), 8)
        own = Solver(sim.calibration).solve(sim.measurement)
        marks, default = scene["marks"], scene["default"]
        assert default["tolerance"] == own.attrs["stop_tolerance"] and scene["noise"] == own.attrs["noise_estimate"]
        assert (default["iteration"], default["converged"]) == (own.iterations, own.stop_reason == "converged")
        assert default["short_db"] == pytest.approx(scene["answer"]["psnr"] - psnr(own.cube, sim.truth), abs=1e-9)
        assert scene["answer"]["psnr"] == marks[-1]["psnr"] and marks[-1]["iteration"] == 1080
        assert scene["stops"][0]["iteration"] == AUTO_AT + FIRST_READING
        needs = scene["needs"]
        assert needs["within"] and all(not bench_answer.stop(marks, scene["answer"], t)["within"]
                                       for t in bench_answer.GRID if t > needs["tolerance"])
    assert sum(s["default"]["converged"] for s in results["scenes"]) >= 1
    late = [{"iteration": k, "psnr": 9.0, "angle": 1.0, "estimate": e} for k, e in ((810, 0.5), (830, 0.5), (835, 0.1))]
    capped = bench_answer.stop(late, {"psnr": 9.0, "angle": 1.0}, 0.2)      # a reading past the cap is not read
    assert (capped["iteration"], capped["converged"]) == (830, False)
    assert bench_answer.stop_cell(capped) == "830 (cap): +0.00 dB / +0.00°"
    at_recount = [{"iteration": k, "psnr": 9.0, "angle": 1.0, "estimate": 0.05} for k in (RECOUNT_AT, RECOUNT_AT + 25)]
    recounted = bench_answer.stop(at_recount, {"psnr": 9.0, "angle": 1.0}, 0.02, 0.07)   # RECOUNT_AT's mark: 0.02
    assert (recounted["iteration"], recounted["tolerance"], recounted["converged"]) == (RECOUNT_AT + 25, 0.07, True)
    assert "| 1 | sources, standard |" in capsys.readouterr().out and (tmp_path / "answer.png").stat().st_size > 0
    with pytest.raises(SystemExit) as refused:
        bench_answer.main([*args[:-5], "1000", "--out", str(tmp_path / "short")])
    assert refused.value.code == 2 and "--iters 1000" in capsys.readouterr().err
    assert not (tmp_path / "short").exists()


def test_bench_admm_sweeps_the_relaxation_with_the_penalties(tmp_path, capsys):
    """One row per combination, α among them; the module's constants are restored."""
    from clsdcam.algorithms.admm import algorithm

    before = algorithm.RELAXATION
    bench_admm.main(["--size", "24x32", "--bands", "4", "--iters", "20", "--marks", "10", "--relaxation", "1,1.7",
                     "--json", str(tmp_path / "a.json")])
    runs = json.loads((tmp_path / "a.json").read_text())["runs"]
    relaxed = [name for name in runs if name.startswith("admm")]
    assert len(relaxed) == 2 and runs[relaxed[0]]["points"] != runs[relaxed[1]]["points"]
    assert algorithm.RELAXATION == before


def test_bench_panel_replays_one_scene_and_judges_a_speed_option(tmp_path, capsys, monkeypatch):
    """``--only I`` runs scene I of the panel alone (the same scene as in the whole panel); ``--also support-field``
    runs that speed option too and judges it by the rule, in its own table."""
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    bench_panel.main(["--size", "24x32", "--bands", "8", "--scenes", "3", "--only", "2", "--marks", "4", "--sweep",
                      "0", "--seed", "7", "--also", "support-field", "--out", str(tmp_path)])
    (scene,) = json.loads((tmp_path / "panel.json").read_text())["scenes"]
    assert scene["index"] == 2 and scene["seed"] == bench_panel.scene_plan(3, 7)[2]["seed"]
    assert set(scene["runs"]) == {"default", "--no-skip", "--support-field"}
    text = capsys.readouterr().out
    assert "`--support-field` against `--no-skip`" in text and text.count("| sparse | 1 |") == 2
    assert "\n| 2 | sparse |" in text
    results = json.loads((tmp_path / "panel.json").read_text())
    assert [title for title, _ in bench_panel.margin_panels(results)] == [          # no sweep: no empty panel
        "default against --no-skip, worst mark", "--support-field against --no-skip, worst mark"]
    assert (tmp_path / "curves.png").stat().st_size > 0


def test_bench_panel_judges_each_run_at_its_own_stop_with_marks_auto(tmp_path, capsys, monkeypatch):
    """``--marks auto``: every configuration, the sweep's weights too, runs to the default stop and is judged at its
    final cube (the default's is the cube a plain default solve gives); ``--only I,J`` keeps those scenes."""
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    bench_panel.main(["--size", "24x32", "--bands", "8", "--scenes", "3", "--only", "0,2", "--marks", "auto",
                      "--sweep", "3", "--seed", "7", "--out", str(tmp_path)])
    results = json.loads((tmp_path / "panel.json").read_text())
    assert results["marks"] == "auto" and [s["index"] for s in results["scenes"]] == [0, 2]
    for scene in results["scenes"]:
        for run in scene["runs"].values():
            (point,) = run["points"]
            assert run["stop_reason"] == "converged" and AUTO_AT < point["iteration"] < AUTO_CAP
    plan = bench_panel.scene_plan(3, 7)[2]
    sim = bench_panel.panel_scene(plan, (24, 32), 8)
    plain = Solver(sim.calibration, settings=Settings()).solve(sim.measurement)
    (own,) = results["scenes"][1]["runs"]["default"]["points"]
    assert own["iteration"] == plain.iterations and own["psnr"] == pytest.approx(psnr(plain.cube, sim.truth), abs=1e-9)
    assert "| 2 | sparse |" in capsys.readouterr().out and (tmp_path / "curves.png").stat().st_size > 0


def test_bench_panel_judges_admm_at_a_third_of_the_iterations(tmp_path, capsys, monkeypatch):
    """``--also 'algorithm admm'``: the same rule at every mark, and ADMM's mark m/3 against --no-skip's m."""
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    bench_panel.main(["--size", "24x32", "--bands", "8", "--scenes", "1", "--marks", "3,9", "--sweep", "0",
                      "--seed", "7", "--also", "algorithm admm", "--out", str(tmp_path)])
    (scene,) = json.loads((tmp_path / "panel.json").read_text())["scenes"]
    admm, full = ({p["iteration"]: p for p in scene["runs"][name]["points"]} for name in ("--algorithm admm",
                                                                                         "--no-skip"))
    psnr_margin, _ = bench_panel.third_margins(scene, "--algorithm admm")
    assert psnr_margin == pytest.approx(admm[3]["psnr"] - full[9]["psnr"] + bench_panel.PSNR_MARGIN_DB)
    assert "`--algorithm admm` at a third of `--no-skip`'s iterations" in capsys.readouterr().out


def test_the_projected_risk_of_a_row_space_error_is_its_whole_norm():
    """P = Aᵀ(AAᵀ)⁻¹A keeps what lies in A's row space: for e = Aᵀw, eᵀPe = ‖e‖² (conjugate gradients on AAᵀ,
    192 unknowns, 300 steps: within 1e-4, where the residual stalls at 1e-5); a random error keeps far less."""
    from clsdcam.backends.numpy import NumpyBackend
    from clsdcam.camera.model import ForwardModel
    from clsdcam.sim import simulate

    sim = simulate(scene="leds", shape=(12, 16), n_bands=4, seed=3)
    model = ForwardModel(NumpyBackend("float64"), sim.calibration.psf, sim.calibration.filters)
    rng = np.random.default_rng(0)
    for e, row_space in ((model.adjoint(rng.standard_normal((12, 16))), True),
                         (rng.standard_normal(model.cube_shape), False)):
        y = model.forward(e)
        kept = float(np.vdot(y, weight_oracles.normal_solve(model, y, 300))) / float(np.vdot(e, e))
        assert kept == pytest.approx(1.0, rel=1e-4) if row_space else kept < 0.5


def test_weight_oracles_scores_a_sweep_by_the_truth_and_two_oracle_risks(tmp_path, capsys):
    weight_oracles.main(["--size", "24x32", "--bands", "8", "--iters", "20", "--sweep", "3", "--cg", "20",
                         "--seed", "7", "--only", "1", "--out", str(tmp_path)])
    (scene,) = json.loads((tmp_path / "oracles.json").read_text())["scenes"]
    assert scene["index"] == 1 and scene["kind"] == bench_panel.scene_plan(2, 7)[1]["kind"]
    chosen = scene["tv_chosen"]
    assert [row["tv"] for row in scene["rows"]] == pytest.approx([chosen / 10, chosen, chosen * 10])
    assert all(row["predicted"] > 0 and row["projected"] > 0 for row in scene["rows"])
    table = capsys.readouterr().out
    assert table.count("\n| ") == 4 and table.count("*") == 4


def test_compare_recon_passes_the_same_code_and_catches_a_changed_cube(tmp_path, capsys):
    record = ["record", "--size", "24x32", "--full-size", "24x32", "--bands", "8", "--iters", "12", "--frames", "2",
              "--scenes", "target,leds"]
    for name in ("a.npz", "b.npz"):
        assert compare_recon.main(record[:1] + [str(tmp_path / name)] + record[1:]) == 0
    assert compare_recon.main(["compare", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--tol", "0"]) == 0
    assert "16 runs compared, 0 failed" in capsys.readouterr().out
    with np.load(tmp_path / "b.npz") as data:
        arrays = {key: data[key] for key in data.files}
    arrays["panel|leds|default"] = arrays["panel|leds|default"] * (1 + 1e-4)
    np.savez(tmp_path / "c.npz", **arrays)
    assert compare_recon.main(["compare", str(tmp_path / "a.npz"), str(tmp_path / "c.npz")]) == 1
    assert "panel/leds/default: relative L2 1.00e-04" in capsys.readouterr().out


def test_bench_breakdown_charges_each_part_its_own_time_and_opaque_parts_their_insides():
    ticks = iter(range(100))
    clock = bench_breakdown.Clock(now=lambda: next(ticks))
    with clock.running("outer", False):                    # 0 .. 9
        with clock.running("inner", False):                # 1 .. 2
            pass
        with clock.running("check", True):                 # 3 .. 6
            with clock.running("inner", False):            # inside an opaque part: no clock read
                with clock.running("power", True):         # 4 .. 5
                    pass
        with clock.running("inner", False):                # 7 .. 8
            pass
    assert clock.seconds == {"inner": 2, "power": 1, "check": 2, "outer": 4}


def test_bench_breakdown_splits_every_configuration_and_sets_the_fft_floor_beside_it(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert bench_breakdown.main(["--size", "24x32", "--bands", "8", "--iters", "40", "--ranks", "3",
                                 "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    rows = result["configurations"]
    assert set(rows) == {"default", "--subspace", "--rank 3", "--algorithm admm", "--algorithm admm, NumPy's passes"}
    for name, row in rows.items():
        parts = row["per_iteration"]
        assert set(parts) == set(bench_breakdown.PER_ITERATION) and row["iterations"] == 40
        assert parts[bench_breakdown.TRANSFORMS] > 0 and row["fft_floor"] > 0
        assert all(v >= 0 for k, v in parts.items() if k != bench_breakdown.OTHER)
        assert sum(parts.values()) * row["iterations"] == pytest.approx(row["total"] - sum(
            share * row["total"] for share in row["one_off_share"].values()))
    assert rows["--rank 3"]["rank"] == 3 and rows["--rank 3"]["one_off_share"][bench_breakdown.POWER] > 0
    assert rows["default"]["per_iteration"][bench_breakdown.PRIOR] > 0
    for name in ("--algorithm admm", "--algorithm admm, NumPy's passes"):      # its balance at 30, its margin's steps
        assert rows[name]["per_iteration"][bench_breakdown.SPLITS] > 0
        assert rows[name]["per_iteration"][bench_breakdown.MARGIN] > 0
        assert min(rows[name]["one_off_share"][part] for part in (bench_breakdown.SETUP, bench_breakdown.BALANCE)) > 0
    assert rows["default"]["one_off_share"][bench_breakdown.SETUP] == 0
    assert rows["default"]["per_iteration"][bench_breakdown.MARGIN] == 0
    assert "together / FFT floor" in capsys.readouterr().out


def test_bench_breakdown_on_opencl_finishes_the_queue_and_leaves_the_host_floor_out(tmp_path, capsys):
    opencl_device()
    out = tmp_path / "b.json"
    assert bench_breakdown.main(["--backend", "opencl", "--size", "24x32", "--bands", "8", "--iters", "20",
                                 "--ranks", "", "--json", str(out)]) == 0
    rows = json.loads(out.read_text())["configurations"]
    assert set(rows) == {"default", "--subspace", "--algorithm admm"}
    assert all(row["fft_floor"] is None and row["per_iteration"][bench_breakdown.TRANSFORMS] > 0
               for row in rows.values())
    admm = rows["--algorithm admm"]              # its kernels' passes, its margin's kernels and its set-up are charged
    assert admm["per_iteration"][bench_breakdown.SPLITS] > 0 and admm["one_off_share"][bench_breakdown.SETUP] > 0
    assert admm["per_iteration"][bench_breakdown.MARGIN] > 0
    assert "opencl: " in capsys.readouterr().out


@pytest.mark.parametrize("steps", ["compiled", "numpy"])
def test_bench_admm_passes_times_every_pass_and_the_rest_adds_up(tmp_path, capsys, monkeypatch, steps):
    """Every pass of the host steps gets time, the compiled ones each or NumPy's splits as one, and the parts with
    the rest make the solve."""
    from clsdcam.algorithms.admm import algorithm
    from clsdcam.algorithms.admm.host_steps import Splitting

    monkeypatch.setenv("CLSDCAM_THREADS", "1")      # main sets it for the clocks; restored after the test
    if steps == "numpy":
        monkeypatch.setattr(algorithm, "host_steps", lambda: Splitting)
    out = tmp_path / "passes.json"
    assert bench_admm_passes.main(["--size", "24x32", "--bands", "8", "--iters", "12", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    parts = result["ms_per_iteration"]
    timed = set(bench_admm_passes.HOST_PASSES) | (set(bench_admm_passes.COMPILED_PASSES) if steps == "compiled"
                                                   else {bench_admm_passes.NUMPY_SPLITS})
    assert set(parts) == timed | {"the rest"} and result["iterations"] == 12
    assert all(parts[part] > 0 for part in timed)
    assert sum(parts.values()) == pytest.approx(result["total_ms_per_iteration"])
    assert result["steps"] == ("JitSplitting" if steps == "compiled" else "Splitting")
    assert "| **the solve** |" in capsys.readouterr().out


def test_compare_speed_pairs_two_checkouts_and_refuses_a_folder_without_one(tmp_path, capsys):
    repo = Path(compare_speed.__file__).resolve().parent.parent
    out = tmp_path / "speed.json"
    assert compare_speed.main([str(repo), "--size", "24x32", "--bands", "8", "--iters", "5", "--pairs", "2",
                               "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert len(result["pairs"]) == 2 and all(new > 0 and old > 0 for new, old in result["pairs"])
    assert result["median_ratio"] == pytest.approx(np.median([n / o for n, o in result["pairs"]]))
    assert "median ratio" in capsys.readouterr().out
    with pytest.raises(SystemExit, match="no clsdcam checkout"):
        compare_speed.main([str(tmp_path), "--pairs", "1"])


def sweep_scene(index: int, level: str, tau: float, finals: list[tuple[float, float]]) -> dict:
    """A panel scene whose 3-point sweep (0.1τ, τ, 10τ) ends at ``finals`` (PSNR, angle)."""
    chosen = [{"iteration": 400, "psnr": finals[1][0], "angle": finals[1][1]}]
    runs = {"default": {"tv_chosen": tau, "points": chosen}, "--no-skip": {"points": chosen}}
    for m, (db, deg) in zip((0.1, 1.0, 10.0), finals):
        runs[f"--tv {m * tau:.3g}"] = {"points": [{"iteration": 400, "psnr": db, "angle": deg}]}
    return {"index": index, "kind": "piecewise", "level": level, "runs": runs}


def test_weight_factors_counts_the_scenes_each_multiple_of_the_chosen_weight_passes(tmp_path, capsys):
    """Every scene's check of the chosen weight, then per sweep multiple the scenes where that fixed weight is
    within 0.5 dB and 1° of the sweep's best; a later file's scene replaces an earlier one's; --low-light takes τ in
    standard light and its multiple in low."""
    first = {"scenes": [sweep_scene(0, "standard", 1e-3, [(20.0, 9.0), (25.0, 9.0), (24.6, 9.5)]),
                        sweep_scene(1, "low light", 3e-3, [(30.0, 5.0), (30.0, 5.0), (30.0, 5.0)])]}
    second = {"scenes": [sweep_scene(1, "low light", 3e-3, [(10.0, 40.0), (22.0, 20.0), (23.0, 18.0)])]}
    paths = [tmp_path / "a.json", tmp_path / "b.json"]
    for path, panel in zip(paths, (first, second)):
        path.write_text(json.dumps(panel))
    assert weight_factors.main([*map(str, paths), "--low-light", "10"]) == 0
    scenes, factors = (table.splitlines()[2:] for table in capsys.readouterr().out.split("\n\n"))
    assert scenes == ["| 0 | piecewise | standard | 0.001 | 25.00 dB / 9.00° (400) | 25.00 dB / 9.00° (400) | "
                      "×1: 25.00 dB / 9.00° (400) | +0.50 dB / +1.00° |",
                      "| 1 | piecewise | low light | 0.003 | 22.00 dB / 20.00° (400) | 22.00 dB / 20.00° (400) | "
                      "×10: 23.00 dB / 18.00° (400) | **-0.50 dB / -1.00°** |"]
    assert factors == ["| ×0.1 | 0 of 2 | 0, 1 |",
                    "| ×1 | 1 of 2 | 1 |",          # scene 1 (second file): 1 dB under 10τ
                    "| ×10 | 2 of 2 | – |",         # scene 0: 0.4 dB under τ, angle 0.5° worse: within the rule
                    "| ×1 in standard light, ×10 in low light | 2 of 2 | – |"]


def test_weight_rejudge_solves_again_the_scenes_whose_default_weight_changed(tmp_path, capsys, monkeypatch):
    """A scene whose default weight is now another than its panel's is solved again at the default, to its stop, and
    judged against its sweep with that run among the fixed weights; a scene whose weight is the same keeps its sweep's
    verdict and is not solved again; panels of different seeds are refused."""
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    panel = tmp_path / "panel.json"
    bench_panel.main(["--size", "24x32", "--bands", "8", "--scenes", "4", "--only", "3", "--marks", "auto",
                      "--sweep", "3", "--seed", "7", "--out", str(tmp_path)])
    results = json.loads(panel.read_text())
    (scene,) = results["scenes"]
    tau = scene["runs"]["default"]["tv_chosen"]
    scene["runs"]["default"]["tv_chosen"] = 3 * tau              # as if an older rule had chosen 3τ
    older = tmp_path / "older.json"
    older.write_text(json.dumps(results))
    capsys.readouterr()

    assert weight_rejudge.main([str(older)]) == 0
    table = capsys.readouterr().out
    sim = bench_panel.panel_scene(scene, (24, 32), 8)
    now = Solver(sim.calibration).solve(sim.measurement)
    assert now.attrs["tv_chosen"] == pytest.approx(tau)
    now_point = {"iteration": now.iterations, "psnr": psnr(now.cube, sim.truth),
                 "angle": spectral_angle(now.cube, sim.truth)}
    runs = {**scene["runs"], "--tv now": {"points": [now_point]}, "own": {"points": [now_point]}}
    db, deg = bench_panel.sweep_margins({**scene, "runs": runs}, "own")
    likeness = weight_rejudge.chosen_now(sim)["mean_over_peak"]
    assert f"| 3 | lines | standard | {likeness:.4f} | {3 * tau:.3g} → {tau:.3g} |" in table
    assert f"({now.iterations}) | " in table and f"{db:+.2f} dB / {deg:+.2f}°" in table
    then = int(weight_factors.passes(scene, "default"))
    assert f"the default now passes {int(min(db, deg) >= 0)} of 1; the panel's default, {then} of 1" in table

    def no_solve(*args):
        raise AssertionError("a scene whose weight is the panel's is not solved again")

    monkeypatch.setattr(weight_rejudge, "run", no_solve)
    assert weight_rejudge.main([str(panel)]) == 0
    table = capsys.readouterr().out
    assert f"| {tau:.3g} → {tau:.3g} |" in table and f"now passes {then} of 1; the panel's default, {then} of 1" in table

    other = tmp_path / "other.json"
    other.write_text(panel.read_text().replace('"seed": 7', '"seed": 8', 1))
    with pytest.raises(SystemExit) as refused:
        weight_rejudge.main([str(panel), str(other)])
    assert refused.value.code == 2 and "one seed, size and bands" in capsys.readouterr().err


def test_lit_weights_judges_each_v1_against_the_fixed_weights_and_today(tmp_path, capsys, monkeypatch,
                                                                       piecewise_panel):
    """Each V1 is the default solved with that ``lit_variance`` (the weight 0.06·σ̂·σ̂²/(q·V1) on a widely lit scene in
    low light), judged by the weight rule against the fixed multiples and by rule 4 against today's default, and the
    rule is restored; a scene that is not widely lit is skipped unsolved; --join reprints the table, and merges
    another file's runs of the same scene (an earlier rule's, named "σ1 …"), judged beside them."""
    rule = TotalVariation.auto_weight
    monkeypatch.setattr(Admm, "widely_lit_above", 0.0)          # every scene widely lit
    out = tmp_path / "lit"
    assert lit_weights.main(["--size", "24x32", "--bands", "8", "--scenes", "2", "--seed", "7", "--only", "1",
                             "--variances", "3e-4,6e-4", "--out", str(out)]) == 0
    table = capsys.readouterr().out
    assert TotalVariation.auto_weight is rule
    (scene,) = json.loads((out / "lit.json").read_text())["scenes"]
    probe, runs = scene["probe"], scene["runs"]
    noise, q = probe["noise_estimate"], probe["measured_mean_over_peak"]
    assert scene["level"] == "low light" and noise ** 2 / q > 6e-4 and scene["skipped"] is None
    for variance in (3e-4, 6e-4):
        own = runs[f"V1 {variance:g}"]
        assert own["tv_chosen"] == pytest.approx(0.06 * noise * noise ** 2 / (q * variance), rel=1e-6)
        assert f"τ {own['tv_chosen']:.3g}, " in table and lit_margins(runs, own) in table
    assert runs["today"]["algorithm"] == "fista" and runs["today"]["points"][-1]["iteration"] == 300
    assert sorted(r["tv_chosen"] for n, r in runs.items() if "(×" in n) == pytest.approx(
        [m * 0.06 * noise for m in lit_weights.MULTIPLES], rel=1e-3)
    assert lit_weights.main(["--join", str(out / "lit.json")]) == 0
    assert capsys.readouterr().out.strip() == table.strip()

    earlier = runs["--tv " + f"{0.06 * noise:.3g} (×1)"]       # a stand-in for the earlier rule's run
    other = tmp_path / "earlier.json"
    earlier_scene = {**scene, "probe": {"noise_estimate": noise}, "runs": {"σ1 0.01": earlier, "today": runs["today"]}}
    other.write_text(json.dumps({"size": "24x32", "bands": 8, "scenes": [earlier_scene]}))
    assert lit_weights.main(["--join", str(other), str(out / "lit.json")]) == 0
    joined = capsys.readouterr().out
    assert lit_margins(runs, earlier) in joined and f"{q:.3f}" in joined
    assert "σ1 0.01: the weight rule on" in joined and "V1 0.0006: the weight rule on" in joined
    assert joined.count("| 7:1 |") == 1 and "σ1 0.01: the weight rule on 1 of 1" in joined          # one scene

    twice = noise ** 2 / (2 * q)                     # the V1 that gives twice the noise rule's weight
    assert lit_weights.main(["--join", str(out / "lit.json"), "--predict", f"{twice!r},1e-9"]) == 0
    predicted = capsys.readouterr().out
    doubled = runs[next(name for name in runs if name.endswith("(×2)"))]
    assert f"| {lit_weights.point(doubled)}, τ {doubled['tv_chosen']:.3g}, {lit_margins(runs, doubled)} |" in predicted
    ceiling = runs[next(name for name in runs if name.endswith("(×4)"))]      # the cap 0.003 is past ×4: held there
    assert ceiling["tv_chosen"] < TotalVariation.auto_weight.highest == 0.003
    assert f"{lit_weights.point(ceiling)}, τ 0.003, {lit_margins(runs, ceiling)}" in predicted
    assert lit_weights.measured_mean({**scene, "probe": {}, "size": "24x32", "bands": 8}) == pytest.approx(q, rel=1e-6)

    monkeypatch.setattr(lit_weights, "run", lambda *args: pytest.fail("a scene no V1 moves was solved"))
    assert lit_weights.main(["--size", "24x32", "--bands", "8", "--scenes", "2", "--seed", "7", "--only", "1",
                             "--variances", "1", "--out", str(out)]) == 0          # σ̂²/q under V1: the noise rule's
    assert "| the noise rule's weight |" in capsys.readouterr().out
    monkeypatch.setattr(Admm, "widely_lit_above", float("inf"))
    assert lit_weights.main(["--size", "24x32", "--bands", "8", "--scenes", "2", "--seed", "7", "--only", "1",
                             "--out", str(out)]) == 0
    assert "| not widely lit |" in capsys.readouterr().out


def lit_margins(runs: dict, own: dict) -> str:
    """A rule's run's margins as the table says them: the weight rule's against the best fixed run, rule 4's against
    today's."""
    fixed = [r["points"][-1] for name, r in runs.items() if name.startswith("--tv ")]
    best = max(fixed, key=lambda p: p["psnr"])
    last, today = own["points"][-1], runs["today"]["points"][-1]
    weight = min(last["psnr"] - best["psnr"] + 0.5, best["angle"] + 1 - last["angle"])
    regression = max(last["psnr"] - today["psnr"] + 0.2, today["angle"] + 0.5 - last["angle"])
    return f"weight {weight:+.2f}, rule 4 {regression:+.2f}"


@pytest.mark.parametrize("args, said", [
    (["--seed", "7", "--variances", "0,4e-4"], "V1 values are positive"),
    (["--seed", "7", "--variances", "x"], "V1 values are positive"),
    ([], "--seed is required"),
    (["--seed", "7", "--predict", "4e-4"], "--predict judges the runs of --join"),
    (["--join", "NO_SIZE"], "the files must be this tool's lit.json files"),
])
def test_lit_weights_refuses_bad_options_before_writing(tmp_path, capsys, args, said):
    bare = tmp_path / "bare.json"                   # a file without the size and bands its scenes need
    bare.write_text(json.dumps({"scenes": []}))
    args = [str(bare) if a == "NO_SIZE" else a for a in args]
    with pytest.raises(SystemExit) as stop:
        lit_weights.main(["--size", "24x32", "--bands", "8", *args, "--out", str(tmp_path / "out")])
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert stop.value.code == 2 and len(errors) == 1 and said in errors[0]
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("spoil, message", [
    (lambda p: p["scenes"][0]["runs"]["default"].update(tv_chosen=None), "cannot read the panels"),
    (lambda p: p["scenes"][0]["runs"]["default"].update(tv_chosen=0), "weight is not > 0"),
    (lambda p: p["scenes"][0]["runs"].pop("default"), "cannot read the panels"),
    (lambda p: p["scenes"][0].update(level="dusk"), "not a panel scene"),
    (lambda p: p["scenes"][0]["runs"].update({"--tv x": {}}), "cannot read the panels"),
    (lambda p: p.update(size="24by32"), "cannot read the panels"),
    (lambda p: p.update(marks=[10, 20]), "--marks auto"),
    (lambda p: p.update(backend="opencl"), "on NumPy"),
])
def test_weight_rejudge_refuses_a_malformed_panel_before_solving(tmp_path, capsys, monkeypatch, spoil, message):
    """Whatever the judgement would trip on later is one line on stderr, exit 2, before any scene is solved."""
    scene = {"index": 3, "kind": "lines", "level": "standard", "seed": 5,
             "runs": {"default": {"tv_chosen": 1e-4}, "--tv 1e-05": {}, "--tv 1e-04": {}, "--tv 0.001": {}}}
    results = {"seed": 7, "size": "24x32", "bands": 8, "marks": "auto", "backend": "numpy", "scenes": [scene]}
    assert weight_rejudge.checked(json.loads(json.dumps(scene)))          # whole, the panel would be judged
    spoil(results)
    panel = tmp_path / "panel.json"
    panel.write_text(json.dumps(results))
    monkeypatch.setattr(weight_rejudge, "judge", lambda *args: pytest.fail("a malformed panel was judged"))
    with pytest.raises(SystemExit) as refused:
        weight_rejudge.main([str(panel)])
    errors = capsys.readouterr().err.strip().splitlines()
    assert refused.value.code == 2 and "error:" in errors[-1] and message in errors[-1]


PANEL_TOOLS = (bench_panel, bench_converged, bench_stop, bench_answer,     # with --scenes: an index past the panel
               lit_weights)                                             # is refused too


@pytest.mark.parametrize("tool, only", [(tool, only) for tool in (*PANEL_TOOLS, weight_oracles)
                                        for only in ("a", "1.5", "-1", ",", "0,x")] +
                         [(tool, "7") for tool in PANEL_TOOLS])
def test_panel_tools_refuse_an_only_that_names_no_scene_of_the_panel(tmp_path, capsys, tool, only):
    """--only must list whole scene indices from 0, within the panel where the tool has --scenes: anything else
    is one line on stderr, exit 2, before a scene runs or a folder is made."""
    panel = ["--scenes", "3"] if tool in PANEL_TOOLS else []
    with pytest.raises(SystemExit) as stop:
        tool.main(["--size", "24x32", "--bands", "8", *panel, "--seed", "7", "--only", only,
                   "--out", str(tmp_path / "out")])
    errors = [line for line in capsys.readouterr().err.splitlines() if "error:" in line]
    assert stop.value.code == 2 and len(errors) == 1 and "--only" in errors[0]
    assert not (tmp_path / "out").exists()


def test_bench_panel_on_opencl_gives_numpys_figures(tmp_path, monkeypatch):
    """``--backend opencl``: every solve of one replayed scene (FISTA and ADMM) runs on one OpenCL backend made for
    the run, recorded as such, and its PSNRs and angles equal NumPy's to 1e-3."""
    opencl_device()
    monkeypatch.setattr(bench_panel, "KINDS", {k: v for k, v in bench_panel.KINDS.items() if k != "real"})
    monkeypatch.setattr(bench_accuracy.Where, "backend", "numpy")
    runs = {}
    for backend in ("numpy", "opencl"):
        out = tmp_path / backend
        bench_panel.main(["--size", "24x32", "--bands", "8", "--scenes", "2", "--only", "1", "--marks", "3,6",
                          "--sweep", "0", "--seed", "7", "--also", "algorithm admm", "--backend", backend,
                          "--out", str(out)])
        results = json.loads((out / "panel.json").read_text())
        assert results["backend"] == backend
        runs[backend] = results["scenes"][0]["runs"]
    assert bench_accuracy.Where.backend.name == "opencl"
    for name, run in runs["numpy"].items():
        for ours, theirs in zip(runs["opencl"][name]["points"], run["points"]):
            assert ours["psnr"] == pytest.approx(theirs["psnr"], abs=1e-3)
            assert ours["angle"] == pytest.approx(theirs["angle"], abs=1e-3)
