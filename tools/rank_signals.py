#!/usr/bin/env python3
"""What a subspace-size rule can read from the band iterate: the lit spectra's eigenvalues while band space runs.

    python tools/rank_signals.py --size 320x448 --bands 64 --at 20,30,40,50 --out rank-signals

For each scene, the default solver runs in band space only (``--rank K``: its warm-up continued, same skips and
weights; the iterate is ``--subspace``'s own until it enters its subspace, at a settle check from
iteration 20 on), and at each iteration of ``--at`` the lit unit spectra of the iterate's sensor window give the
Gram eigenvalues e_1 ≥ e_2 ≥ … ≥ 0, Σ e_j = 1 (:class:`clsdcam.solve.subspace.Spectra`). Printed beside each other:

* the automatic rule's entry rank, the fewest directions leaving a mean sin² of at most ``ENTRY_TAIL`` outside;
* the two largest eigenvalue gaps, ratio_j = e_j / max(e_{j+1}, ROUND_OFF) for j ≤ K/2 with e_j > ROUND_OFF (so a
  noiseless cube's round-off tail counts as zero and its last direction shows as e_j/1e-12);
* the truth's rank: the same rule on the simulated cube's own lit spectra (its content, no reconstruction error);
* the space the run stayed in (``final_rank`` = K: band space).

``docs/benchmarks.md`` sets these beside the basis size each scene needs (``bench_accuracy.py --ranks``).
Writes ``rank_signals.json`` and ``rank_signals.md``.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_accuracy import panel_parser, report, save_json, size_text  # noqa: E402  (the panel's scenes and options)

from clsdcam.solve.space_policy import ENTRY_TAIL, MAX_RANK_FRACTION  # noqa: E402
from clsdcam.sim import simulate  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402
from clsdcam.solve.subspace import Spectra, lit_shapes  # noqa: E402

ROUND_OFF = 1e-12


def signals(cube: np.ndarray) -> dict:
    """The rule's rank, the (at most two) largest eigenvalue gaps [rank j, ratio_j] (see the module docstring), and
    the eigenvalues the ratios read, e_1…e_{n+1} (n = K/2 ratios, fewer for K < 4)."""
    spectra = Spectra.of_shapes(lit_shapes(cube))
    energies = spectra.energies
    n = min(max(int(cube.shape[0] * MAX_RANK_FRACTION), 1), len(energies) - 1)     # ratios need an e_{j+1}
    ratios = np.where(energies[:n] > ROUND_OFF, energies[:n] / np.maximum(energies[1:n + 1], ROUND_OFF), 0.0)
    gaps = [[int(j) + 1, float(ratios[j])] for j in np.argsort(ratios)[::-1][:2] if ratios[j] > 0]
    return {"rule_rank": spectra.rank_for(ENTRY_TAIL), "gaps": gaps, "energies": [float(e) for e in energies[:n + 1]]}


def run_scene(scene: str, shape, bands: int, at) -> dict:
    """The truth's signals and the band iterate's at each iteration of ``at``."""
    sim = simulate(scene=scene, shape=shape, n_bands=bands, seed=0)
    solver = Solver(sim.calibration, settings=Settings(iters=max(at), rank=bands))
    result = solver.solve(sim.measurement, snapshots=at)
    return {"truth": signals(np.asarray(sim.truth)), "final_rank": result.attrs["final_rank"],
            "iterates": {str(k): signals(cube) for k, cube in sorted(result.snapshots.items())}}


def markdown(results: dict) -> str:
    lines = ["| scene | iteration | rule's rank | largest gap: rank (e_j/e_j+1) | next gap |",
             "|---|---:|---:|---|---|"]
    for scene, run in results["scenes"].items():
        rows = [("truth", run["truth"])] + list(run["iterates"].items())
        for name, s in rows:
            gaps = [f"{j} ({ratio:.3g})" for j, ratio in s["gaps"]] + ["—"] * (2 - len(s["gaps"]))
            lines.append(f"| {scene} | {name} | {s['rule_rank']} | {gaps[0]} | {gaps[1]} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = panel_parser(__doc__.splitlines()[0], "rank-signals")
    parser.add_argument("--at", default="20,30,40,50", help="band-space iterations to read the spectra at")
    args = parser.parse_args(argv)
    at = [int(k) for k in args.at.split(",")]
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"size": size_text(args.size), "bands": args.bands, "entry_tail": ENTRY_TAIL, "scenes": {}}
    for scene in args.scenes.split(","):
        results["scenes"][scene] = run_scene(scene, args.size, args.bands, at)
        save_json(out, "rank_signals", results)
        print(f"  {scene} done", file=sys.stderr, flush=True)
    report(out, "rank_signals", results, markdown(results))
    return 0


if __name__ == "__main__":
    sys.exit(main())
