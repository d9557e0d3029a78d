"""OpenCL vs NumPy: every primitive case (``clsdcam/backends/cases.py``), the forward model and a whole
reconstruction.

Runs on the device ``cl_devices.choose_device()`` picks (PYOPENCL_CTX names another; PoCL in CI, a GPU when
one is lent; ``tests/test_portability.py`` runs this file on every installed OpenCL platform), on each code
path the device runs (host and device on CPU devices; ``--cl-path`` keeps one) and every FFT engine of each;
``--cl-tiny`` keeps the problems tiny for interpreting devices (Oclgrind). Skipped cleanly when there is no
OpenCL platform.
Tolerances, relative to max|reference|: the cases' rules (elementwise 1e-6, FFT-based 2e-6 + 5e-7·log10(N),
reductions 1e-5).
"""
from dataclasses import replace
from functools import partial

import numpy as np
import pytest
from conftest import opencl_device

from clsdcam.backends.numpy import NumpyBackend
from clsdcam.errors import InputError

pytestmark = pytest.mark.opencl
DEVICE = opencl_device()

from clsdcam.backends import cl_devices  # noqa: E402
from clsdcam.backends.base import HOST_CODE  # noqa: E402
from clsdcam.backends.cases import (CASES, ELEMENTWISE, REDUCTION, Inputs, case_names, fft_tolerance,  # noqa: E402
                                    relative_error)
from clsdcam.backends.cl_host import MappedHostCode  # noqa: E402
from clsdcam.backends.cl_kernel_code import KernelCode  # noqa: E402
from clsdcam.backends.convolution import HostPathConvolution, PrimitiveConvolution  # noqa: E402
from clsdcam.backends.fft import ReiknaFFT, available_engines  # noqa: E402
from clsdcam.backends.opencl import OpenCLBackend  # noqa: E402
from clsdcam.camera.geometry import default_field_shape  # noqa: E402

CPU = cl_devices.is_cpu(DEVICE)
DTYPES = ["float32"] + (["float64"] if cl_devices.has_fp64(DEVICE) else [])
# every FFT engine of each path: "host" is the host path (CPU devices), the others the device path
PATH_ENGINES = {"host": available_engines("host"), "device": available_engines("device") + ["reikna-unpacked"]}
PATH_BACKEND = {"host": "host", "device": "reikna"}      # the engine of a path's tests without FFTs
K, FIELD, SENSOR = 3, (22, 30), (11, 15)      # the primitive cases' size (the sensor window at the centre)
# reconstructions: (sensor, bands, iterations) of the simulated scene; --cl-tiny: 10 band-space iterations, then 2
# in the subspace
RECONSTRUCTION = {False: ((32, 48), 8, 50), True: ((12, 16), 4, 12)}
# the tiny reconstructions' band-space cube (bands, the paper's field), a transform test's shape: Oclgrind's
# FFT-engine run (tests/test_portability.py) builds each engine's plans for it there, and whole reconstructions
# through one engine only
TINY_CUBE = (RECONSTRUCTION[True][1], *default_field_shape(RECONSTRUCTION[True][0]))
ALL_PRIORS = {"tv": 3e-3, "lowrank": 0.02, "l1": 1e-3, "rank": 3}
# the first set on the support-sized field's geometry (--support-field; at 32×48 the paper's field size with the
# window one pixel off centre), the others on the default's paper field
PRIOR_SETS = [{"tv": 3e-3, "rank": 3, "support_field": True}, ALL_PRIORS, {"spectral": 0.05, "rank": 3}, {"skip": False}]


def device_paths(config) -> list[str]:
    """The code paths under test: those the device runs (host on CPU devices, device everywhere), --cl-path's."""
    chosen = config.getoption("--cl-path")
    return [path for path in (["host"] if CPU else []) + ["device"] if chosen in ("all", path)]


def pytest_generate_tests(metafunc):
    """``path``: each path under test; ``engine``: every FFT engine of each; ``priors``: the reconstructions' prior
    sets (one, every prior, under --cl-tiny)."""
    paths = device_paths(metafunc.config)
    if "path" in metafunc.fixturenames:
        metafunc.parametrize("path", paths)
    if "engine" in metafunc.fixturenames:
        metafunc.parametrize("engine", [engine for path in paths for engine in PATH_ENGINES[path]])
    if "priors" in metafunc.fixturenames:
        metafunc.parametrize("priors", [ALL_PRIORS] if metafunc.config.getoption("--cl-tiny") else PRIOR_SETS)

_BACKENDS: dict = {}


def opencl(dtype="float32", engine="reikna", kahan=None) -> OpenCLBackend:
    """One backend per (dtype, engine, accumulator) for the whole session (PoCL compiles slowly)."""
    key = (dtype, engine, kahan)
    if key not in _BACKENDS:
        _BACKENDS[key] = new_backend(dtype, engine, kahan)
    return _BACKENDS[key]


def new_backend(dtype, engine, kahan=None) -> OpenCLBackend:
    """A backend on DEVICE whose engine names its path: host for "host", device for the others
    ("reikna-unpacked": reikna with one band per complex transform)."""
    base = "reikna" if engine == "reikna-unpacked" else engine
    backend = OpenCLBackend(dtype, device=DEVICE, fft=base, path="host" if base == "host" else "device", kahan=kahan)
    if engine == "reikna-unpacked":
        backend.fft = ReiknaFFT(backend.kernels, pack=False)
        backend.fft_engine = "reikna-unpacked"
    return backend


def assert_case(case: str, dtype, backend, seed: int = 0, tolerance: float | None = None):
    """One primitive case on ``backend`` against NumPy, within its rule (or ``tolerance``)."""
    a = Inputs(K, SENSOR, FIELD, dtype, seed)
    limit = CASES[case].tolerance(a) if tolerance is None else tolerance
    assert CASES[case].error(backend, NumpyBackend(dtype), a) <= limit


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", case_names("elementwise"))
def test_elementwise(case, dtype, path):
    assert_case(case, dtype, opencl(dtype, PATH_BACKEND[path]))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", case_names("reduction"))
def test_reduction(case, dtype, path):
    assert_case(case, dtype, opencl(dtype, PATH_BACKEND[path]))


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("case", case_names("fft"))
def test_fft(case, dtype, engine):
    assert_case(case, dtype, opencl(dtype, engine))


@pytest.mark.parametrize("shape", [(2, 21, 31), (2, 43, 32), (5, 16, 9), (3, 21, 35), (1, 7, 6), TINY_CUBE])
def test_fft_odd_shapes_and_band_counts(shape, engine):
    """Odd sizes, odd band counts (one unpaired band when packing), a single band, planes with a prime factor
    above 7 (VkFFT hands those to reikna), and the tiny reconstructions' cube."""
    be, ref = opencl("float32", engine), NumpyBackend("float32")
    x = np.random.default_rng(3).standard_normal(shape).astype(np.float32)
    spectrum = be.fft2(be.to_device(x))
    tolerance = fft_tolerance(shape[1] * shape[2])
    assert relative_error(be.to_host(spectrum), ref.fft2(x)) <= tolerance
    assert relative_error(be.to_host(be.ifft2(spectrum, shape[1:])), x) <= tolerance


def test_vkfft_transforms_7_smooth_planes_itself_and_hands_the_others_to_reikna():
    pytest.importorskip("pyvkfft")
    be = opencl("float32", "vkfft")
    assert be.fft.engine_for((2, 21, 35)) is be.fft and be.fft.engine_for((4, 640, 896)) is be.fft
    assert [be.fft.engine_for(shape).name for shape in ((2, 21, 31), (1, 43, 32), (1, 62, 64))] == ["reikna"] * 3


@pytest.mark.parametrize("kahan", [None, True])
def test_reductions_over_ten_million_terms(kahan, cl_tiny):
    """vdot/l1/amax over 10⁷+1 float32 terms against float64 NumPy (also the Kahan float32 path)."""
    if cl_tiny:
        pytest.skip("--cl-tiny: no ten-million-term sums on an interpreting device")
    be = opencl("float32", kahan=kahan)
    x = np.random.default_rng(5).random(10_000_001).astype(np.float32) + np.float32(0.5)
    x64 = x.astype(np.float64)
    dx = be.to_device(x)
    assert abs(be.vdot(dx, dx) - np.dot(x64, x64)) <= 1e-5 * np.dot(x64, x64)
    assert abs(be.l1_norm(dx) - np.sum(x64)) <= 1e-5 * np.sum(x64)
    assert be.amax(dx) == float(np.max(x))


def test_float64_on_device_without_fp64_is_an_input_error(monkeypatch):
    monkeypatch.setattr(cl_devices, "has_fp64", lambda device: False)
    with pytest.raises(InputError, match="double precision"):
        cl_devices.require_dtype(DEVICE, "float64")


def test_memory_check_names_sizes_and_remedies():
    be = opencl()
    need = cl_devices.problem_bytes((320, 448), (640, 896), 64)[0]
    assert need > 6 * 64 * 640 * 896 * 4
    with pytest.raises(InputError, match="MiB.*fewer bands"):
        be.check_memory(DEVICE.global_mem_size * 2)
    with pytest.raises(InputError, match="per buffer"):
        be.check_memory(1, largest=DEVICE.max_mem_alloc_size + 1)


def test_unknown_device_lists_the_available_ones():
    with pytest.raises(InputError, match="available"):
        cl_devices.choose_device("no-such-device-xyz")
    assert "fp64" in cl_devices.format_devices()


# ---- the model and the solver --------------------------------------------------------------

@pytest.mark.parametrize("field", [None, (25, 33)])
def test_forward_model_and_adjoint(field, engine):
    from clsdcam.camera.model import ForwardModel

    rng = np.random.default_rng(7)
    psf, filters = rng.random(SENSOR), rng.random((K, *SENSOR))
    ref = ForwardModel(NumpyBackend("float32"), psf, filters, field_shape=field)
    model = ForwardModel(opencl("float32", engine), psf, filters, field_shape=field)
    v = rng.standard_normal(ref.cube_shape).astype(np.float32)
    r = rng.standard_normal(SENSOR).astype(np.float32)
    n = ref.field_shape[0] * ref.field_shape[1]
    forward = model.backend.to_host(model.forward(model.backend.to_device(v)))
    adjoint = model.backend.to_host(model.adjoint(model.backend.to_device(r)))
    assert relative_error(forward, ref.forward(v)) <= fft_tolerance(n)
    assert relative_error(adjoint, ref.adjoint(r)) <= fft_tolerance(n)
    assert model.lipschitz() == pytest.approx(ref.lipschitz(), rel=1e-5)


@pytest.mark.parametrize("field", [None, (25, 33)])
def test_a_window_embedded_on_the_device_is_placed_at_the_offset(field, engine):
    """embed uploads the window and pads it on the device: the field is the window placed at the model's offset and
    zero elsewhere, built here by slicing, a (K, H, W) window as it is, one of one band or an (H, W) plane spread over
    every band as NumPy's assignment spreads it; and the zero start is made on the device."""
    from clsdcam.camera.model import ForwardModel

    rng = np.random.default_rng(9)
    psf, filters = rng.random(SENSOR), rng.random((K, *SENSOR))
    model = ForwardModel(opencl("float32", engine), psf, filters, field_shape=field)
    (oy, ox), (h, w) = model.offset, SENSOR
    cube = rng.random((K, *SENSOR))
    for window in (cube, cube[:1], cube[0]):
        want = np.zeros(model.cube_shape, np.float32)
        want[:, oy:oy + h, ox:ox + w] = window
        assert np.array_equal(model.backend.to_host(model.embed(window)), want)
    assert np.array_equal(model.backend.to_host(model.zero_field()), np.zeros(model.cube_shape, np.float32))


def test_the_probes_window_reading_on_the_device_is_the_windows_own(engine):
    """The auto weights' reading of an iterate's window, p = mean/peak, from two reductions over the window cropped on
    the device (nothing downloaded): the window's own to the reductions' rule (1e-5 relative; NumPy's float64 sum to
    1e-12), from a field whose margin (4) is brighter than the window's peak (at most 1), which a reading must not
    see; and 1 for a dark window."""
    from types import SimpleNamespace

    from clsdcam.camera.model import ForwardModel
    from clsdcam.solve.auto_weights import window_reading

    rng = np.random.default_rng(10)
    psf, filters = rng.random(SENSOR), rng.random((K, *SENSOR))
    bright = (rng.random((K, *SENSOR)) ** 4).astype(np.float32)
    readings = []
    for be in (NumpyBackend("float32"), opencl("float32", engine)):
        model = ForwardModel(be, psf, filters)
        (oy, ox), (h, w) = model.offset, SENSOR
        problem = SimpleNamespace(backend=be, model=model, solution=lambda x: x)
        got = []
        for window in (bright, np.zeros_like(bright)):
            field = np.full(model.cube_shape, 4.0, np.float32)          # a margin brighter than the window
            field[:, oy:oy + h, ox:ox + w] = window
            got.append(window_reading(problem, be.to_device(field)))
        readings.append(got)
    want = bright.mean(dtype=np.float64) / bright.max()
    assert readings[0][0] == (pytest.approx(want, rel=1e-12), bright.size, K)
    assert readings[1][0] == (pytest.approx(want, rel=1e-5), bright.size, K)
    assert readings[0][1][0] == readings[1][1][0] == 1.0


@pytest.fixture(scope="module")
def simulation(cl_tiny):
    from clsdcam.sim import simulate

    shape, bands, _ = RECONSTRUCTION[cl_tiny]
    return simulate(scene="leds", shape=shape, n_bands=bands, seed=0)


def test_convolution_with_unseen_bands_and_fused_step(engine):
    """The model's convolution on OpenCL (mapped host pipeline or primitives) against NumPy's, bands 1 and 3 unseen."""
    from clsdcam.camera.geometry import support_geometry, transfer_function

    rng = np.random.default_rng(8)
    psf, filters = np.zeros(SENSOR), rng.random((5, *SENSOR))
    psf[2:9, 3:12] = rng.random((7, 9))
    filters[[1, 3]] = 0.0
    ref_be, be = NumpyBackend("float32"), opencl("float32", engine)
    geometry = support_geometry(psf, ref_be.fast_length)
    transfer = transfer_function(psf, geometry)
    ref, got = (b.convolution(transfer, filters, geometry.field) for b in (ref_be, be))
    v, y = (rng.standard_normal((5, *geometry.field)).astype(np.float32) for _ in range(2))
    r = rng.standard_normal(SENSOR).astype(np.float32)
    tolerance = fft_tolerance(geometry.voxels_per_band)
    forward = be.to_host(got.forward(be.to_device(v), be.empty(SENSOR)))
    assert relative_error(forward, ref.forward(v, np.empty(SENSOR, np.float32))) <= tolerance
    step = be.to_device(y)
    got.adjoint(be.to_device(r), step, step, 0.4)                     # out is y: the fused gradient step
    assert relative_error(be.to_host(step), ref.adjoint(r, np.empty_like(v), y, 0.4)) <= tolerance
    apart = be.empty(v.shape)
    got.adjoint(be.to_device(r), apart, be.to_device(y), 0.4)          # out apart from y
    assert relative_error(be.to_host(apart), ref.adjoint(r, np.empty_like(v), y, 0.4)) <= tolerance


def test_the_path_decides_which_code_runs():
    """Host path: A and the HOST_CODE primitives are the mapped host code and the FFT is pocketfft; device path:
    kernels, A from primitives and a device FFT; asking for the host path on a GPU, or an engine of the other path,
    is refused."""
    transfer, filters = np.ones((FIELD[0], FIELD[1] // 2 + 1), np.complex64), np.ones((K, *SENSOR), np.float32)
    device = opencl("float32", "reikna")
    assert device.path == "device" and device.fft_engine == "reikna" and isinstance(device.code, KernelCode)
    assert isinstance(device.convolution(transfer, filters, FIELD), PrimitiveConvolution)
    assert all(callable(getattr(device.code, name)) for name in HOST_CODE)
    if CPU:
        host = opencl("float32", "host")
        assert host.path == "host" and host.fft_engine == "host" and isinstance(host.code, MappedHostCode)
        assert isinstance(host.convolution(transfer, filters, FIELD), HostPathConvolution)
        assert all(callable(getattr(host.code, name)) for name in HOST_CODE)
        with pytest.raises(InputError, match="not an engine of the host path"):
            OpenCLBackend("float32", device=DEVICE, fft="reikna", path="host")
    with pytest.raises(InputError, match="not an engine of the device path"):
        OpenCLBackend("float32", device=DEVICE, fft="host", path="device")


# the primitives with host code on the host path, on both paths; float32 sums of r and K products in another
# order than BLAS's
HOST_PATH_CASES = {"subspace_tv": 10 * ELEMENTWISE, "subspace_tv_weighted": 10 * ELEMENTWISE,
                   "bandmix": 10 * ELEMENTWISE, "bandmix_alias": 10 * ELEMENTWISE, "bandmix_expand": 10 * ELEMENTWISE,
                   "bandmix_project": 10 * ELEMENTWISE, "bandmix_projector": 10 * ELEMENTWISE, "gram": REDUCTION,
                   "tv_norm": REDUCTION, "tv_norm_xy": REDUCTION}


def test_device_bandmix_uploads_a_matrix_once_and_keeps_the_recently_used(monkeypatch):
    """A subspace mixes by B and Bᵀ every iteration: each is uploaded the first time only, and one-off matrices in
    between push out the least recently used, not B."""
    import clsdcam.backends.cl_kernel_code as code

    backend = opencl()
    uploads = []
    to_device = code.cla.to_device
    monkeypatch.setattr(code.cla, "to_device", lambda *a, **k: uploads.append(a[1].shape) or to_device(*a, **k))
    rng = np.random.default_rng(4)
    x = backend.to_device(rng.random((4, 6, 5)))
    basis = rng.random((3, 4))
    expected = NumpyBackend("float32").bandmix(backend.to_host(x), basis)
    for step in range(2 * code.MATRICES):
        np.testing.assert_allclose(backend.to_host(backend.bandmix(x, basis)), expected, rtol=1e-6)
        backend.bandmix(x, rng.random((2, 4)))                     # a one-off matrix each time
    assert uploads.count((3, 4)) == 1 and uploads.count((2, 4)) == 2 * code.MATRICES


@pytest.mark.parametrize("group", [None, 64])
@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("rows, cols", [(1, 33), (9, 31), (70, 70), (130, 9)])
def test_device_bandmix_across_tiles_chunks_and_row_blocks(rows, cols, dtype, group, monkeypatch):
    """The device path's bandmix (bandmix.cl) where its work-groups' edges fall: 35 pixels (a tile and a part),
    inputs of 31, 33 and 70 bands (a local-memory chunk holds 32), outputs of one row block to 17 (130 bands: three
    groups along the rows, each of 8 blocks); and on a device whose groups hold 64 work items (2 row blocks each)."""
    rng = np.random.default_rng(rows + cols)
    x, matrix = rng.standard_normal((cols, 5, 7)).astype(dtype), rng.standard_normal((rows, cols))
    be = opencl(dtype, "reikna")
    if group is not None:
        monkeypatch.setattr(be.kernels, "max_group", group)
    got = be.to_host(be.bandmix(be.to_device(x), matrix))
    assert relative_error(got, NumpyBackend(dtype).bandmix(x, matrix)) <= 10 * ELEMENTWISE


def test_bandmix_constants_match_the_kernel():
    """The launch's tile and rows (cl_kernel_code) are the kernel's #defines: a mismatch would index past the tile."""
    import clsdcam.backends.cl_kernel_code as code
    from clsdcam.backends.cl_program import kernel_dir

    source = (kernel_dir() / "bandmix.cl").read_text()
    for name in ("BANDMIX_ROWS", "BANDMIX_TILE"):
        assert f"#define {name} {getattr(code, name)}\n" in source


@pytest.mark.parametrize("case", HOST_PATH_CASES)
def test_host_code_primitives_on_both_paths(case, path):
    assert_case(case, "float32", opencl("float32", PATH_BACKEND[path]), seed=4, tolerance=HOST_PATH_CASES[case])


def test_host_memory_of_a_dropped_buffer_is_kept_until_its_queued_work_is_done():
    """CPU devices: a buffer over our NumPy memory, dropped by Python, keeps that memory until a marker queued at
    its drop has completed (the queue's events decide, not reference counts); then it is let go."""
    be = opencl("float32")
    if be.allocator is None:
        pytest.skip("device memory of its own: the driver owns it")
    be.queue.finish()
    be.allocator.release_finished()
    assert be.allocator.retiring() == 0
    kept, dropped = be.to_device(np.ones(64, np.float32)), be.to_device(np.ones(1 << 20, np.float32))
    be.scale(2.0, dropped, out=dropped)                        # work queued on it
    del dropped
    assert be.allocator.retiring() == 1                        # its memory is held by the retirement marker
    assert be.vdot(kept, kept) == 64.0                         # a blocking read: the queue has passed the marker
    assert be.allocator.retiring() == 0 and be.to_host(kept).sum() == 64.0


def test_a_dropped_allocator_waits_for_its_queue_before_its_memory_goes():
    """CPU devices: when the allocator itself is dropped (its backend gone, or at exit), the memory it still holds
    for dropped buffers goes only after the queue has finished (the queue is held shut here by a user event)."""
    import threading

    import pyopencl as cl

    from clsdcam.backends.cl_memory import HostBuffers

    be = opencl("float32")
    if be.allocator is None:
        pytest.skip("device memory of its own: the driver owns it")
    allocator, opened = HostBuffers(be.queue), []
    buffer, gate = allocator(4096), cl.UserEvent(be.queue.context)
    cl.enqueue_marker(be.queue, wait_for=[gate])               # nothing queued after this runs until the gate opens
    del buffer                                                 # its memory waits behind the gate
    assert allocator.retiring() == 1

    def open_gate():
        opened.append(True)
        gate.set_status(cl.command_execution_status.COMPLETE)

    threading.Timer(0.3, open_gate).start()
    del allocator                                              # returns only once the queue has finished
    assert opened


def test_dropped_temporaries_do_not_corrupt_later_results(cl_tiny):
    """A device input dropped right after its kernel is queued (its host memory is ours on CPU devices) keeps
    its memory until the queue has done with it: mixes of temporaries stay exact, call after call."""
    if cl_tiny:
        pytest.skip("--cl-tiny: cubes of 64 bands are too large for an interpreting device")
    ref, rng = NumpyBackend("float32"), np.random.default_rng(9)
    be = opencl("float32", "reikna")                               # the kernels: their inputs are dropped at once
    for shape, rows in [((64, 300, 41), 6), ((64, 4, 4), 64)] * 3:
        x, matrix = rng.standard_normal(shape).astype(np.float32), rng.standard_normal((rows, shape[0]))
        assert relative_error(be.to_host(be.bandmix(be.to_device(x), matrix)), ref.bandmix(x, matrix)) <= 1e-5


def test_reconstruction_matches_numpy(simulation, priors, engine, cl_tiny):
    """50 float32 FISTA iterations on a simulated scene (band space and subspaces, every prior, tv auto; --cl-tiny:
    12): cubes agree to 1e-4 (relative L2)."""
    assert_reconstructs(simulation, priors, opencl("float32", engine), RECONSTRUCTION[cl_tiny][2])


def test_primitives_read_only_memory_they_wrote(simulation, engine, cl_tiny, garbage_memory):
    """Every new device array starts as NaN, as a GPU's fresh memory is garbage: a reconstruction with every prior,
    in band space and in the subspace, still matches NumPy (what Oclgrind's uninitialised-value check looks for,
    here on any device and through every FFT engine)."""
    assert_reconstructs(simulation, ALL_PRIORS, new_backend("float32", engine), RECONSTRUCTION[cl_tiny][2])


@pytest.fixture
def garbage_memory(monkeypatch):
    """pyopencl.array.empty (every device array the backends allocate) fills each new array with 0xFF bytes (NaN)."""
    import pyopencl as cl
    import pyopencl.array as cla

    empty = cla.empty

    def garbage(queue, shape, dtype, *args, **kwargs):
        array = empty(queue, shape, dtype, *args, **kwargs)
        if array.nbytes:
            cl.enqueue_fill_buffer(queue, array.base_data, np.uint8(0xFF), array.offset, array.nbytes)
        return array

    monkeypatch.setattr(cla, "empty", garbage)


def assert_reconstructs(simulation, priors, backend, iters):
    """``iters`` float32 FISTA iterations on ``backend`` against NumPy's: the same ranks (the subspace when a rank is
    asked for), cubes within 1e-4 (relative L2)."""
    from clsdcam import Settings, Solver

    settings = Settings(iters=iters, **priors)
    ref = Solver(simulation.calibration, backend=NumpyBackend("float32"), settings=settings).solve(simulation.measurement)
    got = Solver(simulation.calibration, backend=backend, settings=settings).solve(simulation.measurement)
    assert got.attrs["backend"] == "opencl" and got.iterations == iters
    assert [r["rank"] for r in got.history] == [r["rank"] for r in ref.history]     # the same skips taken
    bands = simulation.calibration.filters.shape[0]
    assert (min(r["rank"] for r in got.history) < bands) == bool(settings.rank)    # the subspace path when asked
    error = np.linalg.norm(got.cube - ref.cube) / np.linalg.norm(ref.cube)
    assert error <= 1e-4


# ---- ADMM's steps (algorithms/admm: kernel_steps against host_steps) ----------------------------------------
STATE = ("v", "hv", "x", "xi", "rho", "w", "eta", "s", "rest")
RELAXATION = 1.7     # the splits are compared over-relaxed, as the default runs them


TV_AXES = {"every axis": (1.0, 0.5, 2.0), "not λ": (1.0, 1.0, 0.0), "x only": (1.0, 0.0, 0.0), "no TV": None}  # x, y, λ


def admm_pair(dtype, backend, tv_weights=TV_AXES["every axis"], n_bands=5):
    """ADMM's steps on an ``n_bands``-band camera of 6×7 pixels (TV with ``tv_weights`` along x, y, λ as
    ``--tv-weights``, or none; L1; a positive b), NumPy's (the reference, not the compiled passes the host runs where
    Numba is installed: tests/test_admm.py compares those with NumPy's) and on ``backend``, with the same
    penalties."""
    from unittest import mock

    from clsdcam.camera.model import ForwardModel
    from clsdcam.solve.priors import Sparsity, TotalVariation
    from clsdcam.solve.solver import Settings
    from clsdcam.algorithms.admm import algorithm, band_steps
    from clsdcam.algorithms.admm.host_steps import Splitting
    from clsdcam.algorithms.admm.terms import Penalties
    from clsdcam.solve.problem import Problem

    rng = np.random.default_rng(5)
    psf, filters, b = rng.random((6, 7)), rng.random((n_bands, 6, 7)), rng.random((6, 7))
    pair = []
    for be in (NumpyBackend(dtype), backend):
        model = ForwardModel(be, psf, filters)
        priors = [Sparsity(be, 0.4, None)]
        if tv_weights is not None:
            priors.append(TotalVariation(be, 0.05, Settings(tv_weights=tv_weights)))
        with mock.patch.object(algorithm, "host_steps", lambda: Splitting):
            split = band_steps(Problem(model, be.to_device(b), None, None, model.n_bands, priors=priors,
                                       filters=filters))
        split.set_penalties(Penalties(data=0.3, tv=0.7, nonneg=1.3, tv_balance=(0.6, 1.7, 1.2)))
        pair.append(split)
    return pair


def random_states(pair, backend):
    """The same state on both sides of ``pair``, every array random (normal), the kernels' as they keep it (the
    data split over the field; :func:`host_state` gives NumPy's its own), and two random spectra for the solve along
    λ apart from them: (NumPy's state, the kernels', the spectra). Made directly, with no transform (Oclgrind checks
    reikna's kernels for races only)."""
    from clsdcam.algorithms.admm.terms import SplitState

    rng, split = np.random.default_rng(6), pair[0]
    cube, bands = split.shape, split.n_bands
    axes = (len(split.axes),)
    shapes = dict(v=cube, hv=cube, x=cube, xi=(bands,) + split.sensor_shape, rho=cube, w=cube, eta=axes + cube,
                  s=axes + cube, rest=cube)
    host = {name: rng.standard_normal(shape).astype(split.dtype) for name, shape in shapes.items()}
    spectrum = (bands, split.field_shape[0], split.field_shape[1] // 2 + 1)
    spectra = tuple((rng.standard_normal(spectrum) + 1j * rng.standard_normal(spectrum)).astype(split.cdtype)
                    for _ in range(2))
    got = SplitState(**{name: backend.to_device(a) for name, a in host.items()},
                     spectra=tuple(backend.to_device(s, complex_=True) for s in spectra))
    return host_state(split, host), got, spectra


def host_state(split, field: dict):
    """NumPy's state for the kernels' arrays ``field`` (host copies, Hv over the field in ``hv``): x and ξ on the
    window, y = αHv + (1 − α)(x − ξ) as Ŷ and on the window in ``hv``, what its c-step would have left (host_steps'
    module docstring)."""
    from clsdcam.algorithms.admm.terms import SplitState

    (h, w), alpha = split.sensor_shape, split.relaxation
    relaxed = alpha * field["hv"] + (1 - alpha) * field["x"]
    relaxed[:, :h, :w] -= (1 - alpha) * field["xi"]
    window = {"hv": relaxed[:, :h, :w].astype(split.dtype), "x": np.array(field["x"][:, :h, :w])}
    spectrum = (split.n_bands, split.field_shape[0], split.field_shape[1] // 2 + 1)
    return SplitState(**{name: np.array(a) for name, a in field.items()} | window,
                      spectra=tuple(np.zeros(spectrum, split.cdtype) for _ in range(2)),
                      data_spectrum=np.fft.rfft2(relaxed).astype(split.cdtype))


def data_split_field(split, state) -> tuple[np.ndarray, np.ndarray]:
    """NumPy's (x, x − ξ) over the field after the splits, from Ŷ and the window's arrays."""
    (h, w), x = split.sensor_shape, split.data_split(state)
    y = x.copy()
    y[:, :h, :w] -= state.xi
    return x, y


def assert_states_match(pair, ref, got, backend, tolerance):
    """Every array alike after the splits, the data split's over the field: the kernels' x and x − ξ (in ``hv``)
    against NumPy's from Ŷ and its window's arrays."""
    x, y = data_split_field(pair[0], ref)
    theirs = {name: getattr(ref, name) for name in STATE} | {"x": x, "hv": y}
    for name in STATE:
        ours = backend.to_host(getattr(got, name))
        ref = theirs[name]
        assert ours.shape == ref.shape and (not ours.size or relative_error(ours, ref) <= tolerance), name


def flat_numbers(numbers) -> np.ndarray:
    """(data, (step, norm)) as [data, step, norm]."""
    data, (step, norm) = numbers
    return np.array([data, step, norm])


def assert_band_solves_match(pair, spectra, backend, tolerance):
    """The c-step's solve along λ from the same two spectra (x − ξ's and the rest's; NumPy's Ŷ given as its sum with
    the window's change): v̂ alike, and NumPy's Ŷ then αĤv̂ + (1 − α)Ŷ with the kernels' Ĥv̂."""
    data, rest = (backend.to_device(s.copy(), complex_=True) for s in spectra)
    pair[1]._band_solve(data, rest)
    change = (0.3 * spectra[1]).astype(spectra[0].dtype)
    kept, solved = spectra[0] - change, spectra[1].copy()
    pair[0]._band_solve(kept, change, solved)
    alpha = pair[0].relaxation
    assert relative_error(backend.to_host(data), solved) <= tolerance
    assert relative_error(kept, alpha * backend.to_host(rest) + (1 - alpha) * spectra[0]) <= tolerance


@pytest.mark.parametrize("axes", list(TV_AXES))
@pytest.mark.parametrize("dtype", DTYPES)
def test_admm_splits_tv_adjoint_and_band_solve_match_numpy(dtype, axes, path):
    """From the same random state: the splits (x-, w- and u-steps with their duals and sums, over-relaxed; the data
    split's compared over the field, where NumPy keeps it as a spectrum and the window), the TV adjoint and the
    c-step's solve along λ (the right-hand side, the sweeps, Ĥ·v̂), and every dual's rescaling for new penalties,
    agree with NumPy's to the elementwise rule (float64: 1e-12), with TV on every axis, on some (the kernels skip
    the others), or none (zero-size split arrays); each axis with its own TV penalty."""
    backend = opencl(dtype, PATH_BACKEND[path])
    pair = admm_pair(dtype, backend, TV_AXES[axes])
    assert type(pair[0]).__name__ == "Splitting"
    assert [len(split.axes) for split in pair] == [3 - TV_AXES[axes].count(0.0) if TV_AXES[axes] else 0] * 2
    ref, got, spectra = random_states(pair, backend)
    tolerance = 2e-6 if dtype == "float32" else 1e-12

    def splits_agree(ref):
        numbers = [flat_numbers(split.splits(state, RELAXATION)) for split, state in zip(pair, (ref, got))]
        assert np.allclose(numbers[1], numbers[0], rtol=tolerance, atol=0)
        assert_states_match(pair, ref, got, backend, tolerance)

    splits_agree(ref)
    for split, state in zip(pair, (ref, got)):
        split._add_tv_adjoint(state)
    assert_states_match(pair, ref, got, backend, tolerance)
    assert_band_solves_match(pair, spectra, backend, tolerance)
    for split, state in zip(pair, (ref, got)):
        split.rescale_tv_duals(state, {0: 0.3, 1: 2.5, 2: 1.1})
    assert_states_match(pair, ref, got, backend, tolerance)
    from clsdcam.algorithms.admm.balance import repenalise

    for split, state, be in zip(pair, (ref, got), (NumpyBackend(dtype), backend)):
        old = split.penalties
        repenalise(split, state, be, replace(old.scaled(0.5), nonneg=0.3 * old.nonneg))
    assert_states_match(pair, ref, got, backend, tolerance)
    # the splits under the new penalties, from the kernels' arrays as they are (``hv`` read as Hv)
    splits_agree(host_state(pair[0], {name: backend.to_host(getattr(got, name)) for name in STATE}))


@pytest.mark.parametrize("n_bands", [1, 2])
@pytest.mark.parametrize("dtype", DTYPES)
def test_admm_band_solve_matches_numpy_on_one_and_two_bands(dtype, n_bands, path):
    """The c-step's solve along λ at the sweeps' edge cases (one band: no coupling, the last pivot the only one; two:
    no interior band), TV on every axis: v̂ and Ĥ·v̂ agree with NumPy's to the elementwise rule."""
    backend = opencl(dtype, PATH_BACKEND[path])
    pair = admm_pair(dtype, backend, n_bands=n_bands)
    assert [split.n_bands for split in pair] == [n_bands] * 2 and pair[0].coupling > 0
    assert_band_solves_match(pair, random_states(pair, backend)[2], backend, 2e-6 if dtype == "float32" else 1e-12)


# the precisions of ADMM's one-off kernels: (dtype, kahan) with the float64 accumulators a device with fp64 has, and
# the compensated float32 ones of a device without
ONE_OFF_PRECISIONS = dict([(dtype, (dtype, None)) for dtype in DTYPES] + [("float32-kahan", ("float32", True))])


@pytest.mark.parametrize("n_bands", [1, 2, 64])
@pytest.mark.parametrize("dtype, kahan", list(ONE_OFF_PRECISIONS.values()), ids=list(ONE_OFF_PRECISIONS))
def test_admm_band_pivots_kernel_matches_band_pivots(dtype, kahan, n_bands, path):
    """admm_band_pivots, the c-step's pivots formed on the device, against :func:`band_pivots` (the host's float64
    recursion) from the same diagonal a and coupling e, for the camera's penalties (e·m_j below 0.16) and λ's penalty
    up to 66 times a (the last pivot near the system's singularity); on one band (no coupling), two (no interior band)
    and 64. With fp64 (float64 accumulators) the kernel's arithmetic is the host's, so each pivot is the host's
    rounded once to the working precision: within half a unit in its last place (equal, measured), and the host's
    recursion is not run. A device without fp64 (compensated float32 accumulators) takes the host's pivots instead: a
    float32 recursion was 2.6e-6 off at 66, its error growing with the system's conditioning. Without its e²·m_{j−1}
    term a pivot is up to 2 % off with the camera's penalties."""
    from clsdcam.algorithms.admm.terms import Penalties, band_pivots

    backend = opencl(dtype, PATH_BACKEND[path], kahan)
    split = admm_pair(dtype, backend, n_bands=n_bands)[1]
    in_float64 = np.promote_types(backend.kernels.acc, dtype) == np.float64
    strong = Penalties(data=0.01, tv=0.7, nonneg=0.01, tv_balance=(64.0, 1.7, 1.2))
    for penalties in [split.penalties, strong]:
        split.set_penalties(penalties)
        terms = split.terms.for_penalties(penalties, split.axes)
        assert terms.coupling > 0
        on_device = backend.to_host(split._pivots)
        if in_float64:
            assert "pivots" not in vars(terms)                     # the host's recursion not run
            want = band_pivots(terms.diagonal, terms.coupling, n_bands)
            assert np.max(np.abs(on_device - want) / want) <= np.finfo(dtype).eps / 2
        else:
            assert np.array_equal(on_device, terms.pivots)


@pytest.mark.parametrize("axes", ["every axis", "not λ", "x only"])
@pytest.mark.parametrize("dtype, kahan, group", [(*precision, None) for precision in ONE_OFF_PRECISIONS.values()]
                         + [("float32", None, 4)], ids=list(ONE_OFF_PRECISIONS) + ["float32-groups-of-4"])
def test_admm_difference_rms_kernel_matches_the_hosts(dtype, kahan, group, axes, path, monkeypatch):
    """The balance's rms(D_d w) on the device (admm_difference_squares, one reduction over w) against the host's
    :func:`difference_rms` from the same non-negative w, for TV on every axis or on some: along λ the last band's
    difference 0, along y and x circular. The host sums each band's squares by a float32 dot product (168 terms
    here) and the kernel in its accumulators (a row's 14 plainly, the rows' compensated without fp64): the
    reductions' rule 1e-5 (float64: 1e-12). The kernel's 60 rows are fewer than a group: in groups of 4 several
    groups share them and each work item sums several, as at full size. A circular λ would raise its RMS by 13 %
    here, a y or an x that stops at the edge lower theirs by 5 % and 4 %."""
    from types import SimpleNamespace

    backend = opencl(dtype, PATH_BACKEND[path], kahan)
    if group is not None:
        monkeypatch.setattr(backend.kernels, "local_1d", group)
    pair = admm_pair(dtype, backend, TV_AXES[axes])
    w = (np.random.default_rng(8).random(pair[0].shape) ** 3).astype(dtype)
    want = pair[0].difference_rms(SimpleNamespace(w=w))
    got = pair[1].difference_rms(SimpleNamespace(w=backend.to_device(w)))
    assert sorted(got) == sorted(want) == pair[0].axes
    tolerance = 1e-5 if dtype == "float32" else 1e-12
    assert all(got[axis] == pytest.approx(want[axis], rel=tolerance, abs=0.0) for axis in want)


def test_admm_reconstruction_matches_numpy(simulation, engine, cl_tiny, garbage_memory):
    """float32 ADMM (TV and L1, the margin's correction on) on a simulated scene, every new device array starting as
    NaN (a GPU's garbage): the cube agrees with NumPy's to 1e-4 (relative L2) after as many iterations as FISTA's
    test."""
    priors = {"algorithm": "admm", "tv": 3e-3, "l1": 1e-3}
    assert_reconstructs(simulation, priors, new_backend("float32", engine), RECONSTRUCTION[cl_tiny][2])


def test_admm_reconstruction_resumes_a_video_frame_on_the_device_as_numpy_does(simulation, engine, cl_tiny):
    """A second frame (half as bright) resumes from the first's splits and duals, rescaled on the device: its cube
    matches NumPy's second frame to 1e-4 (relative L2), and the device's upload of the terms is made once (the x-step's
    gains formed inline, never on the host)."""
    from clsdcam import Settings, Solver
    from clsdcam.algorithms.admm.terms import TERMS_KEY

    settings, iters = Settings(iters=RECONSTRUCTION[cl_tiny][2], algorithm="admm", tv=3e-3), 5
    cubes, uploaded = [], []
    for backend in (NumpyBackend("float32"), new_backend("float32", engine)):
        solver = Solver(simulation.calibration, backend=backend, settings=settings)
        state = solver.solve(simulation.measurement).state
        assert state.carry is not None
        uploaded.append({name: kept[2] for name, kept in solver.shared[TERMS_KEY]._uploads.items()})
        cubes.append(solver.solve(0.5 * simulation.measurement, state=state, iters=iters).cube)
        uploaded.append({name: kept[2] for name, kept in solver.shared[TERMS_KEY]._uploads.items()})
    assert uploaded[0] == uploaded[1] == {}                                      # NumPy uploads nothing
    assert set(uploaded[2]) == {"filters", "transfer", "reciprocal", "data transfer", "pivots"}
    assert all(uploaded[3][name] is array for name, array in uploaded[2].items())    # the same device arrays
    assert "gain" not in vars(solver.shared[TERMS_KEY]._last[1])                  # the host's gains never formed
    assert np.linalg.norm(cubes[1] - cubes[0]) / np.linalg.norm(cubes[0]) <= 1e-4


def test_admm_kernels_track_the_margins_band_of_the_x_steps_relaxed_point(engine, monkeypatch):
    """The margin's correction on the kernels (clsdcam/algorithms/admm/margin.py), which corrects at every c-step:
    after each of 12 relaxed iterations' c-step, the tracked band Q is the band of rfft2(αHv + (1 − α)x + ξ), the
    x-step's relaxed point, to float32's rounding (2e-6 of its largest coefficient, the recursion's rounding decaying
    by (2 − α)/2 an iteration); new data penalties start it again from ξ, and it goes on matching. Every c-step's
    correction moves v̂'s band."""
    from clsdcam.algorithms.admm.balance import repenalise
    from clsdcam.algorithms.admm.margin_kernels import KernelMarginCorrection

    moves, correct = [], KernelMarginCorrection.correct

    def watched(margin, state, data, rest):
        before = margin.correction.band.take(backend.to_host(data))
        correct(margin, state, data, rest)
        moves.append(np.abs(margin.correction.band.take(backend.to_host(data)) - before).max())

    monkeypatch.setattr(KernelMarginCorrection, "correct", watched)
    backend = new_backend("float32", engine)
    split = admm_pair("float32", backend, n_bands=3)[1]
    assert split.margin is not None and split.relaxation != 1
    state, _ = split.start(backend.to_device(np.random.default_rng(9).random(split.shape)))
    for iteration in range(12):
        if iteration == 6:
            repenalise(split, state, backend, replace(split.penalties, data=2 * split.penalties.data))
            assert state.margin_band is None
        split.c_step(state)
        tracked = backend.to_host(state.margin_band)
        assert relative_peak_error(tracked, relaxed_point_band(split, state, backend)) <= 2e-6
        split.splits(state, split.relaxation)
    assert len(moves) == 12 and min(moves) > 0


@pytest.mark.parametrize("restart", [False, True], ids=["tracked", "xi-transformed"])
@pytest.mark.parametrize("dtype, kahan, group", [("float32", None, None), ("float32", True, None),
                                                  ("float64", None, None), ("float32", None, 16)],
                         ids=["float32", "float32-kahan", "float64", "float32-groups-of-16"])
def test_admm_margin_correction_kernels_match_the_hosts(dtype, kahan, group, restart, path, monkeypatch):
    """The margin's kernels against :class:`MarginCorrection` on the host, from random spectra: x̂'s band from
    the data split's band D and the tracked Q (or from ξ's transform, where the band starts again), then v̂ = v̂₀ + δ̂
    and Ĥv̂ written into the two spectra's bands (the rest of each untouched) and the next Q. The correction's ten
    conjugate-gradient steps carry rounding through their inner products: 5e-6 of the largest coefficient in float32
    (5–10e-7 measured), with float64 accumulators or compensated float32 ones (a device without fp64), 1e-13 in float64
    (1e-15 measured); the correction itself is a tenth or more of v̂₀'s band here, so a missing one fails. A mode's
    plane of 77 coefficients is smaller than the largest group, so each item takes one (as at full size, 150 in a group
    of 256 on a GPU): in a group of 16 each takes several."""
    from types import SimpleNamespace

    backend, rng = opencl(dtype, PATH_BACKEND[path], kahan), np.random.default_rng(12)
    if group is not None:
        monkeypatch.setattr(backend.kernels, "row_groups", partial(type(backend.kernels).row_groups, backend.kernels,
                                                                   cap=group))
    split = admm_pair(dtype, backend, n_bands=5)[1]
    device, host, band = split.margin, split.margin.correction, split.margin.correction.band
    spectrum = (split.n_bands, split.field_shape[0], split.field_shape[1] // 2 + 1)
    d, v0, rest = ((rng.standard_normal(spectrum) + 1j * rng.standard_normal(spectrum)).astype(split.cdtype)
                   for _ in range(3))
    q = band.take(rng.standard_normal(spectrum) + 1j * rng.standard_normal(spectrum)).astype(split.cdtype)
    xi = rng.standard_normal((split.n_bands,) + split.sensor_shape).astype(split.dtype)
    state = SimpleNamespace(margin_band=None if restart else backend.to_device(q, True), xi=backend.to_device(xi),
                            v=backend.empty(split.shape))                 # the c-step's v, free until its end
    data, rest_device = backend.to_device(d, True), backend.to_device(rest, True)
    device.split(state, data)
    data = backend.to_device(v0, True)
    device.correct(state, data, rest_device)

    dual = host.dual_band(xi) if restart else (q - band.take(d)) * split.dtype.type(0.5)
    x_hat = band.take(d) + dual
    delta = host.correction(band.take(v0), x_hat)
    solved = band.take(v0) + delta
    hv = host.transfer * solved
    tolerance = 5e-6 if dtype == "float32" else 1e-13
    assert np.abs(delta).max() > 0.1 * np.abs(band.take(v0)).max()
    assert relative_peak_error(band.take(backend.to_host(data)), solved) <= tolerance
    assert relative_peak_error(band.take(backend.to_host(rest_device)), hv) <= tolerance
    assert relative_peak_error(backend.to_host(state.margin_band), host.relaxation * hv
                               + (1 - host.relaxation) * x_hat + dual) <= tolerance
    assert np.array_equal(without_band(band, backend.to_host(data)), without_band(band, v0))
    assert np.array_equal(without_band(band, backend.to_host(rest_device)), without_band(band, rest))


def without_band(band, spectrum: np.ndarray) -> np.ndarray:
    """``spectrum`` with its band set to zero (a copy): what the margin's kernels leave as it was."""
    out = spectrum.copy()
    band.add(out, -band.take(out))
    return out


def relaxed_point_band(split, state, backend) -> np.ndarray:
    """The margin's band of rfft2(αHv + (1 − α)x + ξ) after a c-step on the kernels, from the device's arrays."""
    alpha, (h, w) = split.relaxation, split.sensor_shape
    point = alpha * backend.to_host(state.hv).astype(np.float64) + (1 - alpha) * backend.to_host(state.x)
    point[:, :h, :w] += backend.to_host(state.xi)
    return split.margin.correction.band.take(np.fft.rfft2(point))


def relative_peak_error(got, want) -> float:
    return float(np.abs(got - want).max() / np.abs(want).max())
