"""Devices as ``clsdcam check`` and the solver see them: the memory plan of the default problem, the primitive cases
it checks and times, a problem too large for the device (one line, exit 2, nothing solved), and which FFT engine
``auto`` picks on a GPU.

The device is the one ``cl_devices.choose_device()`` picks (PoCL in CI); its reported memory is lowered by
replacing ``cl_devices.memory_limits``, and its type (for the engine rule) by replacing ``opencl.is_cpu``."""
import numpy as np
import pytest
from conftest import opencl_device

pytestmark = pytest.mark.opencl
DEVICE = opencl_device()

from clsdcam import devcheck  # noqa: E402
from clsdcam.backends import cl_devices, fft, opencl  # noqa: E402
from clsdcam.backends.cases import CASES, benchmarks  # noqa: E402
from clsdcam.cli import main  # noqa: E402
from clsdcam.devcheck import DEFAULT_PROBLEM, memory_rows  # noqa: E402

SENSOR, FIELD, BANDS = DEFAULT_PROBLEM
MIB = 1 << 20


def report_memory(monkeypatch, total: int, largest: int | None = None):
    """The device says it has ``total`` bytes, and ``largest`` (default: all of them) per buffer."""
    monkeypatch.setattr(cl_devices, "memory_limits", lambda device: (total, total if largest is None else largest))


def needed(bands: int) -> tuple[int, int]:
    return cl_devices.problem_bytes(SENSOR, FIELD, bands, "float32")


def test_the_memory_plan_of_the_default_problem_fits_a_large_device(monkeypatch):
    report_memory(monkeypatch, 80 << 30)
    rows = {row.name: row for row in memory_rows(opencl.OpenCLBackend("float32", device=DEVICE, path="device"))}
    band_space = rows[f"band space ({BANDS} bands, field {FIELD[0]}×{FIELD[1]})"]
    assert band_space.ok and band_space.detail.endswith("fits")
    assert f"{needed(BANDS)[0] / MIB:.0f} MiB" in band_space.detail
    assert int(rows["bands of that field that fit"].detail.split()[0]) > BANDS
    assert {f"subspace ({BANDS // 2} coefficients)", "one field cube"} <= set(rows)


@pytest.mark.parametrize("limit", ["memory", "buffer"])
def test_the_plan_says_how_many_bands_fit_a_small_device(monkeypatch, limit):
    """Too little memory, or too small a largest buffer: band space fails, and the bands that fit are the most K
    whose problem_bytes fit (K + 1 do not)."""
    total, largest = needed(BANDS)
    small = (total // 3, None) if limit == "memory" else (8 << 30, largest // 3)
    report_memory(monkeypatch, *small)
    rows = {row.name: row for row in memory_rows(opencl.OpenCLBackend("float32", device=DEVICE, path="device"))}
    band_space = next(row for name, row in rows.items() if name.startswith("band space"))
    assert band_space.ok is False and ("per buffer" if limit == "buffer" else "device memory") in band_space.detail
    fit = int(rows["bands of that field that fit"].detail)
    assert 0 < fit < BANDS
    assert cl_devices.shortfall(DEVICE, *needed(fit)) is None and cl_devices.shortfall(DEVICE, *needed(fit + 1))


def test_check_runs_every_primitive_case_and_times_each_benchmark_case(monkeypatch):
    """The parity rows are the case table's at both sizes, each within its case's tolerance; the bandwidth rows are
    each primitive's benchmark case, copy (the roof) first."""
    be = opencl.OpenCLBackend("float32", device=DEVICE, path="device")
    rows = devcheck.parity_rows({"device": be})
    assert [row.name for row in rows] == [f"{name} (device path, {size})" for size in devcheck.SIZES for name in CASES]
    assert all(row.ok for row in rows), [row for row in rows if not row.ok]
    monkeypatch.setattr(devcheck, "TIMED", (2, 16, 24))
    assert [row.name for row in devcheck.bandwidth_rows(be)] == [case.name for case in benchmarks()]
    assert benchmarks()[0].name == "copy"


def test_a_problem_too_large_for_the_device_is_one_line_and_exit_2(monkeypatch, tmp_path, capsys):
    """``clsdcam reconstruct --backend opencl`` on a device too small for the problem: exit 2 before any solve, one
    line naming what it needs, what the device has and how many bands would fit; no output file."""
    import clsdcam.solve.solver

    assert main(["simulate", str(tmp_path), "--size", "32x40", "--bands", "4", "--scene", "leds", "--seed", "3"]) == 0
    monkeypatch.setattr(clsdcam.solve.solver.Solver, "solve",
                        lambda *a, **k: pytest.fail("solved a problem that cannot fit"))
    report_memory(monkeypatch, 64 << 10)
    capsys.readouterr()
    output = tmp_path / "cube.h5"
    code = main(["reconstruct", str(tmp_path / "measurement.npy"), "--calibration", str(tmp_path / "calibration.h5"),
                 "-o", str(output), "--quiet", "--backend", "opencl", "--path", "device", "--iters", "3"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and not output.exists()
    assert err.startswith("clsdcam: error: 4 bands on a") and "\n" not in err
    assert "MiB of device memory" in err and "bands of that field fit" in err and "fewer bands" in err


@pytest.mark.parametrize("installed", [True, False])
def test_auto_takes_vkfft_on_a_gpu_when_installed(monkeypatch, installed):
    """A device that is not a CPU runs the device path, whose automatic FFT engine is VkFFT when pyvkfft imports,
    else reikna; a CPU device's automatic path is the host path and its engine pocketfft. With pyvkfft really
    installed, the engine picked transforms there and back."""
    really = fft.vkfft_available()
    monkeypatch.setattr(fft, "vkfft_available", lambda: installed)
    if cl_devices.is_cpu(DEVICE):
        cpu = opencl.OpenCLBackend("float32", device=DEVICE)
        assert (cpu.path, cpu.fft_engine) == ("host", "host")
    monkeypatch.setattr(opencl, "is_cpu", lambda device: False)
    gpu = opencl.OpenCLBackend("float32", device=DEVICE)
    assert (gpu.path, gpu.fft_engine, gpu.allocator) == ("device", "vkfft" if installed else "reikna", None)
    if really or not installed:
        x = np.random.default_rng(0).random((2, 16, 24), np.float32)
        assert np.allclose(gpu.to_host(gpu.ifft2(gpu.fft2(gpu.to_device(x)), x.shape[1:])), x, atol=1e-5)


def test_the_reconstruction_rows_check_each_algorithm_on_each_path():
    """FISTA (every prior, band space then a subspace) and ADMM (TV and L1) each solve on every path the device runs
    and match NumPy."""
    paths = (["host"] if cl_devices.is_cpu(DEVICE) else []) + ["device"]
    rows = devcheck.reconstruction_rows({path: opencl.OpenCLBackend("float32", device=DEVICE, path=path)
                                         for path in paths})
    assert [row.name.split(",")[0] for row in rows] == ["fista"] * len(paths) + ["admm"] * len(paths)
    assert all(row.ok and row.name.endswith(f"({path} path)") for row, path in zip(rows, paths * 2))


def test_admms_memory_plan_counts_its_own_cubes(monkeypatch):
    """A device that holds FISTA's solve but not ADMM's: the solver refuses ``--algorithm admm`` up front (one
    InputError with the bands that would fit) and builds FISTA's; the plans differ by ADMM's extra field cubes."""
    from clsdcam import Settings, Solver
    from clsdcam.algorithms.admm import Admm
    from clsdcam.errors import InputError
    from clsdcam.sim import simulate

    sim = simulate(scene="leds", shape=(32, 40), n_bands=4, seed=3)
    field = Solver(sim.calibration, backend="numpy").geometry.field
    fista, _ = cl_devices.problem_bytes(sim.calibration.filters.shape[1:], field, 4)
    admm, _ = cl_devices.problem_bytes(sim.calibration.filters.shape[1:], field, 4, field_buffers=Admm.field_buffers)
    assert admm - fista == (Admm.field_buffers - cl_devices.FIELD_BUFFERS) * 4 * field[0] * field[1] * 4
    report_memory(monkeypatch, (fista + admm) // 2)
    backend = opencl.OpenCLBackend("float32", device=DEVICE, path="device")
    assert Solver(sim.calibration, backend=backend, settings=Settings(iters=1)).lipschitz > 0
    with pytest.raises(InputError, match="4 bands on a .* bands of that field fit"):
        Solver(sim.calibration, backend=backend, settings=Settings(iters=1, algorithm="admm"))
