"""``clsdcam check``: what one OpenCL device does for clsdcam, checked against NumPy and timed.

Sections, each a list of rows (name, detail, ok; ok None for figures that pass or fail nothing):

* device: its name, platform, driver, limits (memory, largest buffer, work-group size, compute units, fp64);
* memory: the plan of the default problem (64 bands, sensor 320×448, the paper's 640×896 field) from
  :func:`~clsdcam.backends.cl_devices.problem_bytes`: band space, the most bands of that field that fit, a
  subspace of K/2 coefficients, one field cube; fails when band space (what the solver checks up front) does not
  fit;
* parity: every primitive case (``backends/cases.py``: each primitive of the contract, its aliasing and special
  arguments) against NumPy at two sizes, on each path the device runs (host and device on CPU devices, device
  elsewhere), float32; the cases' tolerances, relative to max|reference|: 1e-6 elementwise (band mixes
  included), 1e-5 reductions, 2e-6 + 5e-7·log10 N for FFTs (pyvkfft's own);
* reconstruction: 30 FISTA iterations with every prior, band space then a rank-3 subspace, and 30 ADMM iterations
  with TV and L1 in band space, against NumPy (relative L2 ≤ 1e-4), on each path;
* fft: each FFT engine's fft2 + ifft2 of a 16 × 256 × 256 cube (ms);
* bandwidth: the device's buffer copy (the roof) and each primitive's benchmark case's GB/s (minimum bytes
  read + written / median time, device path, a 16 × 256 × 256 cube) as a fraction of it.
"""
from __future__ import annotations

import statistics
import time
from dataclasses import asdict, dataclass

import numpy as np

from .backends import CASES, Inputs, NumpyBackend, benchmarks

DEFAULT_PROBLEM = ((320, 448), (640, 896), 64)      # sensor, the paper's field, bands
SIZES = {"small": (3, (11, 15), (22, 30)), "medium": (16, (61, 83), (128, 180))}    # bands, sensor, field
TIMED = (16, 256, 256)                                # the cube the timings use (the sensor: half its sides)
REPEAT = 5


@dataclass
class Row:
    section: str
    name: str
    detail: str
    ok: bool | None = None


# ---- the device and its memory ---------------------------------------------------------------
def device_rows(be) -> list[Row]:
    """The device and the limits clsdcam depends on."""
    from .backends import has_fp64, is_cpu, memory_limits

    d, (memory, largest) = be.device, memory_limits(be.device)
    facts = {"device": be.device_name, "driver": f"{d.driver_version} ({d.version.strip()})",
             "type": "CPU (host and device paths)" if is_cpu(d) else "GPU or accelerator (device path)",
             "global memory": f"{memory >> 20} MiB", "largest buffer": f"{largest >> 20} MiB",
             "local memory": f"{d.local_mem_size >> 10} KiB", "work-group size": str(d.max_work_group_size),
             "compute units": str(d.max_compute_units), "fp64": "yes" if has_fp64(d) else "no (float32 only)"}
    return [Row("device", name, value) for name, value in facts.items()]


def memory_rows(be) -> list[Row]:
    """The default problem's plan: band space (checked, as the solver does: ``check_problem``), how many bands of
    that field fit, a K/2 subspace, one field cube."""
    from .backends import MOST_BANDS, bands_that_fit, problem_bytes, shortfall

    sensor, field, bands = DEFAULT_PROBLEM
    (total, largest), mib = problem_bytes(sensor, field, bands, be.dtype), 1 << 20
    short = shortfall(be.device, total, largest)
    plan = f"band space ({bands} bands, field {field[0]}×{field[1]})"
    fit = bands_that_fit(be.device, sensor, field, be.dtype)
    return [Row("memory", plan, f"{total / mib:.0f} MiB (largest buffer {largest / mib:.0f} MiB): "
                + (short or "fits"), short is None),
            Row("memory", "bands of that field that fit", f"{fit}{' or more' if fit == MOST_BANDS else ''}"),
            Row("memory", f"subspace ({bands // 2} coefficients)",
                f"{problem_bytes(sensor, field, bands // 2, be.dtype)[0] / mib:.0f} MiB"),
            Row("memory", "one field cube", f"{bands * field[0] * field[1] * be.dtype.itemsize / mib:.0f} MiB")]


# ---- parity ----------------------------------------------------------------------------------
def parity_rows(backends: dict) -> list[Row]:
    """Each primitive case on each path's backend against NumPy, at each size."""
    ref, rows = NumpyBackend("float32"), []
    for size, (bands, sensor, field) in SIZES.items():
        a = Inputs(bands, sensor, field)
        for path, be in backends.items():
            for name, case in CASES.items():
                error, limit = case.error(be, ref, a), case.tolerance(a)
                rows.append(Row("parity", f"{name} ({path} path, {size})", f"error {error:.1e} ≤ {limit:.1e}",
                                error <= limit))
    return rows


RECONSTRUCTIONS = {"fista": dict(tv=3e-3, lowrank=0.02, l1=1e-3, rank=3), "admm": dict(algorithm="admm", tv=3e-3, l1=1e-3)}


def reconstruction_rows(backends: dict) -> list[Row]:
    """30 iterations of each algorithm (FISTA with every prior, band space then a rank-3 subspace; ADMM with TV and
    L1) against NumPy, on each path."""
    from .solve.settings import Settings
    from .sim import simulate
    from .solve.solver import Solver

    sim = simulate(scene="leds", shape=(32, 48), n_bands=8, seed=0)
    rows = []
    for algorithm, priors in RECONSTRUCTIONS.items():
        settings = Settings(iters=30, **priors)
        ref = Solver(sim.calibration, backend=NumpyBackend("float32"), settings=settings).solve(sim.measurement).cube
        for path, be in backends.items():
            cube = Solver(sim.calibration, backend=be, settings=settings).solve(sim.measurement).cube
            error = float(np.linalg.norm(cube - ref) / np.linalg.norm(ref))
            rows.append(Row("reconstruction", f"{algorithm}, 8 × 32 × 48, 30 iterations ({path} path)",
                            f"error {error:.1e} ≤ 1e-4", error <= 1e-4))
    return rows


# ---- speed -----------------------------------------------------------------------------------
def median_ms(run, finish, repeat: int = REPEAT) -> float:
    """Median milliseconds of ``repeat`` runs after a warm-up, each synchronised by ``finish``."""
    run()
    finish()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        run()
        finish()
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def fft_rows(device) -> list[Row]:
    """fft2 + ifft2 of the timed cube with each engine of each path the device runs."""
    from .backends import OpenCLBackend, available_engines, is_cpu

    rows = []
    for path in (["host"] if is_cpu(device) else []) + ["device"]:
        for engine in available_engines(path):
            be = OpenCLBackend("float32", device=device, fft=engine, path=path)
            x = be.to_device(np.random.default_rng(0).random(TIMED, np.float32))
            spectrum, back = be.fft2(x), be.empty(TIMED)
            ms = median_ms(lambda: be.ifft2(be.fft2(x, out=spectrum), TIMED[1:], out=back), be.queue.finish)
            rows.append(Row("fft", f"{engine} ({path} path)", f"{ms:.1f} ms per fft2 + ifft2 of {'×'.join(map(str, TIMED))}"))
    return rows


def bandwidth_rows(be) -> list[Row]:
    """The device's copy bandwidth (the roof) and each primitive's benchmark case's GB/s as a share of it."""
    k, h, w = TIMED
    a = Inputs(k, (h // 2, w // 2), (h, w))
    speeds = {case.name: case.moved(a) / median_ms(case.timed(be, a), be.queue.finish) / 1e6 for case in benchmarks()}
    roof = speeds["copy"]
    return [Row("bandwidth", name, f"{gbps:.1f} GB/s" + ("  (the roof)" if name == "copy" else f", {gbps / roof:.0%} of copy"))
            for name, gbps in speeds.items()]


# ---- the whole check -------------------------------------------------------------------------
def check(device: str | None = None, progress=lambda section: None) -> list[Row]:
    """Every section on the device ``device`` names (clsdcam's choice when None)."""
    from .backends import OpenCLBackend, choose_device, is_cpu

    chosen = choose_device(device)
    backends = {path: OpenCLBackend("float32", device=chosen, path=path)
                for path in (["host"] if is_cpu(chosen) else []) + ["device"]}
    device_path = backends["device"]
    sections = [("device", lambda: device_rows(device_path) + memory_rows(device_path)),
                ("parity", lambda: parity_rows(backends)), ("reconstruction", lambda: reconstruction_rows(backends)),
                ("fft", lambda: fft_rows(chosen)), ("bandwidth", lambda: bandwidth_rows(device_path))]
    rows = []
    for name, run in sections:
        progress(name)
        rows += run()
    return rows


def passed(rows: list[Row]) -> bool:
    return all(row.ok is not False for row in rows)


def table(rows: list[Row]) -> str:
    """A plain-text table: section, check, result, PASS/FAIL (blank for figures)."""
    marks = {True: "PASS", False: "FAIL", None: ""}
    cells = [("section", "check", "result", "")] + [(r.section, r.name, r.detail, marks[r.ok]) for r in rows]
    widths = [max(len(c[i]) for c in cells) for i in range(3)]
    lines = ["  ".join(c[i].ljust(widths[i]) for i in range(3)) + "  " + c[3] for c in cells]
    failed = sum(r.ok is False for r in rows)
    return "\n".join(line.rstrip() for line in lines) + f"\n\n{sum(r.ok is True for r in rows)} checks passed, {failed} failed"


def as_json(rows: list[Row]) -> dict:
    return {"passed": passed(rows), "rows": [asdict(r) for r in rows]}
