#!/usr/bin/env python3
"""Where ADMM's iteration goes on the host, pass by pass: one solve of a simulated scene on the NumPy backend, on one
thread, with each of its steps' passes timed.

    python tools/bench_admm_passes.py --size 128x160 --bands 64 --iters 60
    PYTHONPATH=OTHER_CHECKOUT python tools/bench_admm_passes.py --size 128x160 ...   # another checkout's passes

The passes (:mod:`clsdcam.algorithms.admm`): the c-step's forward and inverse transforms (the data split's pruned to
the sensor window apart, where a checkout has them), its solve along λ and the TV adjoint; the x-, w- and u-steps
(each axis's u-step counted together), the compiled ones where Numba is installed (``jit_steps``, the solve along λ
too where a checkout compiles it), else NumPy's (``host_steps``: the x-, w- and u-steps then count as one). A pass's
figure is its wall-clock time in the solve, everything it calls included, in milliseconds per iteration; "the rest"
is the solve's other time (the checkpoints, the records, the driver). A short solve first compiles or loads the passes
and plans the transforms; it is not counted. Timings drift ±30 % between runs: compare two checkouts in alternating
runs, and read each pass against the others in the same run.
"""
from __future__ import annotations

import argparse
import os
import sys
import time
from contextlib import ExitStack
from pathlib import Path
from unittest import mock

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_breakdown import Clock  # noqa: E402
from report import emit  # noqa: E402

# part -> the attribute timed: the c-step's parts on host_steps.Splitting (the compiled steps inherit them, but for
# the solve along λ where they compile it), the compiled passes in jit_steps, or NumPy's splits as one
HOST_PASSES = {"forward transforms": "_rfft2", "inverse transforms": "_irfft2",
               "pruned forward transforms": "_window_rfft2", "pruned inverse transforms": "_irfft2_to_window",
               "solve along λ": "_band_solve", "TV adjoint": "_add_tv_adjoint"}
COMPILED_PASSES = {"x-step": "x_pass", "w-step": "w_pass", "u-step": "u_pass", "solve along λ": "band_pass"}
NUMPY_SPLITS = "x-, w- and u-steps"


def passes() -> dict:
    """part -> (owner, attribute name) to time: the compiled passes where ADMM's host steps are compiled; the parts
    the checkout has."""
    from clsdcam.algorithms.admm import algorithm
    from clsdcam.algorithms.admm.host_steps import Splitting

    parts = {part: (Splitting, name) for part, name in HOST_PASSES.items() if hasattr(Splitting, name)}
    if algorithm.host_steps() is Splitting:
        return parts | {NUMPY_SPLITS: (Splitting, "splits")}
    from clsdcam.algorithms.admm import jit_steps

    return parts | {part: (jit_steps, name) for part, name in COMPILED_PASSES.items() if hasattr(jit_steps, name)}


def timed_solve(sim, iters: int, parts: dict) -> dict:
    """One ADMM solve of ``iters`` iterations with every part wrapped: milliseconds per iteration, part by part."""
    from clsdcam.solve.solver import Settings, Solver

    clock = Clock()
    solver = Solver(sim.calibration, backend="numpy", settings=Settings(iters=iters, algorithm="admm"))
    with ExitStack() as stack:
        for part, (owner, name) in parts.items():
            stack.enter_context(mock.patch.object(owner, name, clock.wrap(getattr(owner, name), part, False)))
        start = time.perf_counter()
        result = solver.solve(sim.measurement)
        total = time.perf_counter() - start
    done = len(result.history)
    per_iteration = {part: 1e3 * clock.seconds.get(part, 0.0) / done for part in parts}
    per_iteration["the rest"] = 1e3 * total / done - sum(per_iteration.values())
    return {"iterations": done, "ms_per_iteration": per_iteration, "total_ms_per_iteration": 1e3 * total / done}


def measure(args) -> dict:
    import clsdcam
    from clsdcam.algorithms.admm import algorithm
    from clsdcam.sim import simulate

    shape = tuple(int(v) for v in args.size.split("x"))
    sim = simulate(scene=args.scene, shape=shape, n_bands=args.bands, seed=args.seed)
    timed_solve(sim, 2, passes())                     # compiles or loads the passes, plans the transforms
    row = timed_solve(sim, args.iters, passes())
    return {"size": shape, "bands": args.bands, "scene": args.scene, "iters": args.iters,
            "steps": algorithm.host_steps().__name__,
            "package": str(Path(clsdcam.__file__).parent), **row}


def table(result: dict) -> str:
    rows = result["ms_per_iteration"]
    lines = [f"| {result['bands']}×{result['size'][0]}×{result['size'][1]}, {result['scene']}, "
             f"{result['iterations']} iterations ({result['steps']}) | ms per iteration | share |", "|---|---:|---:|"]
    total = result["total_ms_per_iteration"]
    lines += [f"| {part} | {ms:.1f} | {100 * ms / total:.0f} % |" for part, ms in rows.items()]
    lines.append(f"| **the solve** | **{total:.1f}** | 100 % |")
    return "\n".join(lines) + f"\n\npackage: {result['package']}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="128x160", help="sensor HxW")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--scene", default="leds", help="a simulated scene (clsdcam demo --scene)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iters", type=int, default=60)
    parser.add_argument("--json")
    args = parser.parse_args(argv)
    os.environ["CLSDCAM_THREADS"] = "1"               # every pass on the solve's thread, so the clocks add up
    result = measure(args)
    return emit(result, table(result), args.json)


if __name__ == "__main__":
    sys.exit(main())
