"""Shared fixtures: the real data beside the repository (skipped cleanly when absent), a known SIGINT handler."""
import os
import signal
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path:
    """``../shared/data`` beside the checkout, or ``$CLSDCAM_DATA`` when set."""
    return Path(os.environ.get("CLSDCAM_DATA", REPO.parent / "shared" / "data"))


@pytest.fixture
def shared_data():
    """Return a function mapping a relative path under shared/data to a Path, skipping if absent."""

    def get(relative: str) -> Path:
        path = shared_data_dir() / relative
        if not path.exists():
            pytest.skip(f"shared data file {relative} is not present")
        return path

    return get


@pytest.fixture
def default_sigint():
    """Python's default SIGINT handler (KeyboardInterrupt) for the test, whatever the runner inherited (a run
    started in the background with ``nohup`` or ``&`` ignores SIGINT); the inherited handler after it."""
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, inherited)


def opencl_device():
    """The OpenCL device clsdcam picks (PYOPENCL_CTX names another); the calling test module is skipped when
    pyopencl or every OpenCL driver is missing."""
    pytest.importorskip("pyopencl")
    from clsdcam.backends import cl_devices
    from clsdcam.errors import InputError

    try:
        return cl_devices.choose_device()
    except InputError as exc:  # pragma: no cover - machines without any OpenCL driver
        pytest.skip(f"no OpenCL device: {exc}", allow_module_level=True)


# ---- the OpenCL parity suite's options (tests/test_parity.py; PYOPENCL_CTX picks its device) ----------------
def pytest_addoption(parser):
    group = parser.getgroup("clsdcam-opencl", "OpenCL parity (tests/test_parity.py; PYOPENCL_CTX picks the device)")
    group.addoption("--cl-path", default="all", choices=("all", "host", "device"),
                    help="the code paths to test on the device: all it runs (host and device on CPUs), or one")
    group.addoption("--cl-tiny", action="store_true",
                    help="tiny problems only, for interpreting devices (Oclgrind): smaller reconstructions, no "
                         "ten-million-term sums")
    group.addoption("--cl-keep-buffers", action="store_true",
                    help="never release an OpenCL buffer (Oclgrind's uninitialised-value check gives a new buffer the "
                         "shadow of a released one with the same index)")


@pytest.fixture(scope="session")
def cl_tiny(request) -> bool:
    """--cl-tiny: tiny problems only (an interpreting device)."""
    return request.config.getoption("--cl-tiny")


@pytest.fixture(scope="session", autouse=True)
def cl_keep_buffers(request):
    """--cl-keep-buffers: every pyopencl Buffer made from here on is kept until the session ends. Oclgrind reuses a
    released buffer's index and its uninitialised-value check keeps that index's old shadow (jrprice/Oclgrind: the
    plugin has no release hook): without this, a new buffer larger than the old one reads as uninitialised."""
    if not request.config.getoption("--cl-keep-buffers"):
        yield
        return
    import pyopencl as cl

    kept, buffer_class = [], cl.Buffer

    class KeptBuffer(buffer_class):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            kept.append(self)

    cl.Buffer = KeptBuffer
    yield
    cl.Buffer = buffer_class


TINY = ["--size", "24x32", "--bands", "4"]      # the smallest simulated camera the command-line tests use


@pytest.fixture(scope="module")
def tiny_sim(tmp_path_factory) -> Path:
    """A tiny simulated camera (``clsdcam simulate`` at TINY): calibration.h5, measurement.npy, truth.h5."""
    from clsdcam.cli import main

    folder = tmp_path_factory.mktemp("tiny") / "sim"
    assert main(["simulate", str(folder), *TINY]) == 0
    return folder
