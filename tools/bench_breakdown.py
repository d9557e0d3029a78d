#!/usr/bin/env python3
"""Where a solve's time goes, part by part, beside the FFT floor of the iteration's own transforms.

    python tools/bench_breakdown.py --size 320x448 --bands 64 --scene leds --iters 300 --ranks 8,16,23 --json b.json
    python tools/bench_breakdown.py --backend opencl ...     # a GPU: the queue finished at every boundary

Each configuration (the default, ``--subspace``, each forced ``--rank``, ``--algorithm admm``, and on NumPy with the
``jit`` extra installed ADMM again on NumPy's passes instead of the compiled ones) is one solve of the
simulated scene, timed by wrapping the package's own functions (:data:`PARTS`): a part's time is its wall-clock time
minus the time of the parts inside it (exclusive), except that an opaque part keeps everything inside it but the
opaque parts (a basis check's transforms count as the check's, its power iteration as a power iteration). The
parts, per iteration:

- transforms: every scipy.fft call the solve's thread makes (the pruned forward and adjoint; ADMM's solve along λ
  counts as its splits);
- filter mix, pad and crop: the rest of A and Aᵀ (the gradient step, the data term of the residual);
- prior and constraint: the prox (TV and v ≥ 0 are one fused pass; in a subspace, B·c and Bᵀ· with it);
- momentum: FISTA's restart test and extrapolation;
- objective checks: F at the checkpoints (in a subspace its g(B·c)), the best iterate kept;
- basis checks: the subspace's full step and the choice of directions every 25 iterations;
- ADMM's splits: the x-, u- and w-steps and duals outside the transforms;
- ADMM's margin correction: its band's split and correction (the host's arithmetic, or the kernels' four launches);
- other: the rest of the solve (its records, the result, the driver's observers).

and the one-off parts, as a share of the whole solve: moves between spaces (building a subspace's filters,
mapping the iterates), power iterations for L, the prior weight's re-estimation, ADMM's set-up (its splitting,
the penalties' terms, the start's splits), ADMM's balance at its iteration 30 (the RMS of its iterate's differences,
host or device, the duals rescaled; the new penalties' terms count as set-up). The FFT floor is the iteration's
own 4r real 2-D transforms of the field (2 rfft2 + 2 irfft2 of r bands, r the rank the solve ended in; K in band
space), measured in the same run (``bench_iteration.floor_timer``: pocketfft on the host, so NumPy's only). A
row's figure is seconds per iteration over the whole solve, so a configuration that starts in band space
(``--subspace``'s warm-up) mixes both. On OpenCL (``--backend opencl``) the clock finishes the device's queue
before every reading, so each part holds its kernels' time, and the solve runs slower than it would unwatched by
one queue round trip per boundary; the transforms are then the FFT engine's calls (``clsdcam.backends.fft``).
Timings drift ±30 % on a shared machine: read the ratios within one run.
"""
from __future__ import annotations

import argparse
import sys
import threading
import time
from contextlib import ExitStack, contextmanager, nullcontext
from pathlib import Path
from unittest import mock

import scipy.fft

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_iteration import floor_timer  # noqa: E402
from report import emit  # noqa: E402

from clsdcam.algorithms.admm import Admm  # noqa: E402
from clsdcam.algorithms.fista import Fista  # noqa: E402
from clsdcam.solve.auto_weights import AutoWeights  # noqa: E402
from clsdcam.backends import fft as device_fft  # noqa: E402
from clsdcam.solve.checkpoints import Checkpoints  # noqa: E402
from clsdcam.camera.model import ForwardModel  # noqa: E402
from clsdcam.solve.phases import Phases  # noqa: E402
from clsdcam.solve.priors import ProxAverage  # noqa: E402
from clsdcam.solve.problem import Problem  # noqa: E402
from clsdcam.sim import simulate  # noqa: E402
from clsdcam.solve.solver import Settings, Solver  # noqa: E402
from clsdcam.algorithms.admm import algorithm as admm_algorithm  # noqa: E402
from clsdcam.algorithms.admm import balance as admm_balance  # noqa: E402
from clsdcam.algorithms.admm.host_steps import Splitting  # noqa: E402
from clsdcam.algorithms.admm.margin import MarginCorrection  # noqa: E402
from clsdcam.algorithms.admm.terms import SplittingBase  # noqa: E402
from clsdcam.solve.subspace import SpectralSubspace  # noqa: E402

TRANSFORMS = "transforms"
FILTERS = "filter mix, pad and crop"
PRIOR = "prior and constraint"
MOMENTUM = "momentum"
OBJECTIVE = "objective checks"
BASIS = "basis checks"
SPLITS = "ADMM's splits"
OTHER = "other"
MOVES = "moves between spaces"
POWER = "power iterations"
WEIGHTS = "weight re-estimation"
SETUP = "ADMM's set-up"
MARGIN = "ADMM's margin correction"
BALANCE = "ADMM's balance"
NUMPY_PASSES = "numpy passes"    # a configuration's field: ADMM on NumPy's passes, the compiled ones installed
PER_ITERATION = (TRANSFORMS, FILTERS, PRIOR, MOMENTUM, OBJECTIVE, BASIS, SPLITS, MARGIN, OTHER)
ONE_OFF = (MOVES, POWER, WEIGHTS, SETUP, BALANCE)
FFT_FUNCTIONS = ("fft", "ifft", "rfft", "irfft", "rfft2", "irfft2", "rfftn", "irfftn")

# (owner, attribute, part, opaque): the functions wrapped; a rename in the package fails tests/test_tools.py
DEVICE_FFTS = [(engine, name, TRANSFORMS, False) for engine in (device_fft.HostFFT, device_fft.ReiknaFFT,
                                                                 device_fft.VkFFT) for name in ("forward", "inverse")]
try:                                   # ADMM's kernels (needs pyopencl)
    from clsdcam.algorithms.admm.kernel_steps import KernelSplitting
    from clsdcam.algorithms.admm.margin_kernels import KernelMarginCorrection
    KERNEL_SPLITTING = [(KernelSplitting, "_band_solve", SPLITS, True), (KernelSplitting, "start", SETUP, True),
                        (KernelSplitting, "set_penalties", SETUP, True),
                        (KernelMarginCorrection, "split", MARGIN, True),
                        (KernelMarginCorrection, "correct", MARGIN, True)]
except ImportError:
    KERNEL_SPLITTING = []
PARTS = [(scipy.fft, name, TRANSFORMS, False) for name in FFT_FUNCTIONS] + DEVICE_FFTS + [
    (Problem, "gradient_step", FILTERS, False),
    (Problem, "residual", FILTERS, False),
    (ProxAverage, "prox", PRIOR, False),
    (SpectralSubspace, "prox", PRIOR, False),
    (Fista, "_stats", MOMENTUM, False),
    (Fista, "_extrapolate", MOMENTUM, False),
    (Admm, "iterate", SPLITS, False),
    (Splitting, "_band_solve", SPLITS, True),
    (MarginCorrection, "data_split", MARGIN, True),
    (MarginCorrection, "correct", MARGIN, True),
    (admm_balance, "balance", BALANCE, True),
    (admm_algorithm, "band_steps", SETUP, True),
    (SplittingBase, "set_penalties", SETUP, True),
    (Splitting, "start", SETUP, True),
    (Checkpoints, "check", OBJECTIVE, True),
    (Checkpoints, "enter", OBJECTIVE, True),
    (Phases, "_check_width", BASIS, True),
    (Phases, "_enter", MOVES, True),
    (Phases, "_move", MOVES, True),
    (Phases, "_leave", MOVES, True),
    (ForwardModel, "lipschitz", POWER, True),
    (AutoWeights, "act", WEIGHTS, True),
] + KERNEL_SPLITTING


class Clock:
    """Exclusive seconds per part: a stack of the parts running, each charged its time minus its children's
    (an opaque part's children are charged to it, except opaque ones), on the thread that made the clock (the
    solve's: calls from row blocks on other threads are inside a part of it already)."""

    def __init__(self, now=time.perf_counter):
        self.now = now
        self.thread = threading.current_thread()
        self.seconds: dict[str, float] = {}
        self._stack: list[list] = []            # [part, opaque, start, seconds charged elsewhere]

    def wrap(self, function, part: str, opaque: bool):
        clock = self

        def timed(*args, **kwargs):
            with clock.running(part, opaque):
                return function(*args, **kwargs)

        return timed

    @contextmanager
    def running(self, part: str, opaque: bool):
        inside_opaque = any(frame[1] for frame in self._stack)
        if threading.current_thread() is not self.thread or (inside_opaque and not opaque):
            yield          # a row block's worker thread, or a plain part inside an opaque one: its caller's time
            return
        frame = [part, opaque, self.now(), 0.0]
        self._stack.append(frame)
        try:
            yield
        finally:
            self._stack.pop()
            spent = self.now() - frame[2]
            self.seconds[part] = self.seconds.get(part, 0.0) + spent - frame[3]
            if self._stack:
                self._stack[-1][3] += spent


@contextmanager
def clocked(clock: Clock):
    """Every function of :data:`PARTS` wrapped by ``clock`` for the duration."""
    with ExitStack() as stack:
        for owner, name, part, opaque in PARTS:
            stack.enter_context(mock.patch.object(owner, name, clock.wrap(getattr(owner, name), part, opaque)))
        yield


def configurations(ranks, admm: bool, host: bool) -> dict:
    """name -> Settings fields; on the ``host`` (NumPy) with the compiled passes installed, ADMM's row again on
    NumPy's passes (the field NUMPY_PASSES)."""
    configs = {"default": {}, "--subspace": {"subspace": True}}
    configs |= {f"--rank {rank}": {"rank": rank} for rank in ranks}
    if admm:
        configs["--algorithm admm"] = {"algorithm": "admm"}
        if host and admm_algorithm.host_steps() is not Splitting:
            configs["--algorithm admm, NumPy's passes"] = {"algorithm": "admm", NUMPY_PASSES: True}
    return configs


def synchronised(backend):
    """The clock's time source: perf_counter, after the device's queue has finished (OpenCL)."""
    queue = getattr(backend, "queue", None)
    if queue is None:
        return time.perf_counter
    return lambda: (queue.finish(), time.perf_counter())[1]


def breakdown(sim, backend: str, fields: dict, iters: int) -> dict:
    """One solve's parts: seconds per iteration, one-off shares, the rank and field it ended in."""
    fields = dict(fields)
    numpy_passes = fields.pop(NUMPY_PASSES, False)
    solver = Solver(sim.calibration, backend=backend, settings=Settings(iters=iters, **fields))
    clock = Clock(synchronised(solver.backend))
    passes = mock.patch.object(admm_algorithm, "host_steps", lambda: Splitting) if numpy_passes else nullcontext()
    with clocked(clock), passes:
        start = clock.now()
        result = solver.solve(sim.measurement)
        total = clock.now() - start
    done = len(result.history)
    seconds = {part: clock.seconds.get(part, 0.0) for part in PER_ITERATION + ONE_OFF}
    seconds[OTHER] = total - sum(seconds.values())
    return {"iterations": done, "total": total, "rank": int(result.history[-1]["rank"]),
            "device": f"{solver.backend.device_name} (FFT {solver.backend.fft_engine})",
            "field": list(solver.geometry.field),
            "per_iteration": {part: seconds[part] / done for part in PER_ITERATION},
            "one_off_share": {part: seconds[part] / total for part in ONE_OFF}}


def measure(args) -> dict:
    shape = tuple(int(v) for v in args.size.split("x"))
    sim = simulate(scene=args.scene, shape=shape, n_bands=args.bands, seed=args.seed)
    ranks = [int(r) for r in args.ranks.split(",") if r]
    rows = {}
    admm = not args.no_admm
    for name, fields in configurations(ranks, admm, args.backend == "numpy").items():
        row = breakdown(sim, args.backend, fields, args.iters)
        row["fft_floor"] = floor_timer(row["rank"], tuple(row["field"]))() if args.backend == "numpy" else None
        rows[name] = row
        print(f"{name} done ({row['total']:.1f} s)", file=sys.stderr)
    return {"size": shape, "bands": args.bands, "scene": args.scene, "seed": args.seed, "iters": args.iters,
            "backend": args.backend, "configurations": rows}


def table(result: dict) -> str:
    rows = result["configurations"]
    names = list(rows)
    head = [f"| {result['bands']}×{result['size'][0]}×{result['size'][1]}, {result['scene']}, "
            f"{result['iters']} iterations: seconds per iteration | " + " | ".join(names) + " |",
            "|---|" + "---:|" * len(names)]
    body = [f"| {part} | " + " | ".join(f"{rows[n]['per_iteration'][part]:.4f}" for n in names) + " |"
            for part in PER_ITERATION]
    whole = {n: sum(rows[n]["per_iteration"].values()) for n in names}
    floors = {n: rows[n]["fft_floor"] for n in names}
    tail = [
        "| **per-iteration parts, together** | " + " | ".join(f"**{whole[n]:.4f}**" for n in names) + " |",
        "| FFT floor: 4r transforms (r = the final rank) | "
        + " | ".join(f"{floors[n]:.4f} (r = {rows[n]['rank']})" if floors[n] else f"— (r = {rows[n]['rank']})"
                     for n in names) + " |",
        "| together / FFT floor | " + " | ".join(f"{whole[n] / floors[n]:.1f}×" if floors[n] else "—"
                                                for n in names) + " |",
        *(f"| one-off: {part}, share of the solve | "
          + " | ".join(f"{100 * rows[n]['one_off_share'][part]:.1f} %" for n in names) + " |" for part in ONE_OFF),
        "| one-off parts together, share of the solve | "
        + " | ".join(f"{100 * sum(rows[n]['one_off_share'].values()):.1f} %" for n in names) + " |",
        "| iterations; whole solve, s | " + " | ".join(f"{rows[n]['iterations']}; {rows[n]['total']:.1f}"
                                                     for n in names) + " |",
    ]
    devices = sorted({row["device"] for row in rows.values()})
    return "\n".join(head + body + tail) + f"\n\n{result['backend']}: " + "; ".join(devices)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", default="320x448", help="sensor HxW")
    parser.add_argument("--bands", type=int, default=64)
    parser.add_argument("--scene", default="leds", help="a simulated scene (clsdcam demo --scene)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--iters", type=int, default=300)
    parser.add_argument("--ranks", default="8,16,23", help="forced ranks, one solve each ('' for none)")
    parser.add_argument("--no-admm", action="store_true",
                        help="leave out --algorithm admm")
    parser.add_argument("--backend", default="numpy", choices=("numpy", "opencl"))
    parser.add_argument("--json")
    args = parser.parse_args(argv)
    result = measure(args)
    return emit(result, table(result), args.json)


if __name__ == "__main__":
    sys.exit(main())
