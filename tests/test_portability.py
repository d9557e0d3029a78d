"""The parity suite (tests/test_parity.py) on the device path (what GPUs run) of every OpenCL implementation this
machine can have: PoCL, Intel's CPU runtime and Oclgrind, each in a process of its own (the ICD loader reads its
variables when pyopencl loads; ``clsdcam.backends.cl_icd`` writes them).

Oclgrind interprets every kernel and checks it: tiny problems, data races and uninitialised values on (out-of-bounds
accesses always are), zero reports. Its uninitialised-value check needs ``-cl-opt-disable`` (optimised vector code
trips it: jrprice/Oclgrind#126 and its shuffle and ``freeze`` handling) and buffers that are never released (see
``--cl-keep-buffers``); reikna's twiddles call ``sincos`` into private memory, which that check cannot follow (a
fatal error in its plugin), and VkFFT's own kernel, run after other plans in one process, reads twiddles that check
calls uninitialised (each VkFFT test alone is clean; its buffers are VkFFT's, which ``--cl-keep-buffers`` cannot
keep). So Oclgrind runs twice. Under every check, the tests that transform nothing: every primitive case and ADMM's
steps (but the margin's band started again from ξ, which transforms ξ: its ``xi-transformed`` cases). That check
does not count ``clEnqueueFillBuffer`` as a write (a kernel reading a filled buffer is reported), so the test that
fills new arrays with NaN to stand for a GPU's garbage (``read_only_memory``) is left out there: the check is that
test, on each primitive. Under the race and bounds checks, the FFT engines: every transform test of each engine, the
margin's ``xi-transformed`` cases, the tiny reconstructions' cube among their shapes, and two whole reconstructions,
FISTA with every prior and ADMM (each a minute or more under the interpreter), through one engine, VkFFT where it is
installed (the GPUs' engine), else packed reikna. An implementation that is not installed is a skip saying how to
install it; one installed but not listed is a failure. The runs on Oclgrind take minutes: the test's limit is
PORTABILITY_TIMEOUT.
"""
from __future__ import annotations

import os
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from dataclasses import dataclass, field
from pathlib import Path

import pytest

pytestmark = pytest.mark.opencl
pytest.importorskip("pyopencl")

from clsdcam.backends import cl_icd  # noqa: E402
from clsdcam.backends.fft import available_engines  # noqa: E402

REPO = Path(__file__).resolve().parent.parent
OCLGRIND = {"OCLGRIND_DATA_RACES": "1"}
OCLGRIND_ALL = {**OCLGRIND, "OCLGRIND_UNINITIALIZED": "1", "OCLGRIND_BUILD_OPTIONS": "-cl-opt-disable"}
NOT_UNDER_ALL_CHECKS = "not reikna and not vkfft and not read_only_memory and not transformed"
TINY = ("--cl-tiny",)
PORTABILITY_TIMEOUT = 1800      # seconds for one implementation's run (pytest-timeout's default is 600)


@dataclass(frozen=True)
class Platform:
    """One run of the parity suite: the implementation (``pocl`` or a ``cl_icd`` name), its platform's name (for
    PYOPENCL_CTX), the suite's options, extra variables, the FFT engines whose tests must pass, and the tests (by
    name, before the parameters) that must pass."""

    name: str
    implementation: str
    platform: str
    options: tuple = ()
    env: dict = field(default_factory=dict)
    engines: tuple = ()
    tests: tuple = ()


DEVICE_ENGINES = tuple(available_engines("device")) + ("reikna-unpacked",)
FFT_CHECKED_ENGINES = ("reikna", "reikna-unpacked") + (("vkfft",) if "vkfft" in DEVICE_ENGINES else ())
# The FFT engines under the race and bounds checks (the module docstring). The whole reconstructions run through one
# engine: through packed reikna, with the NaN-filled one through VkFFT too, they took 277 s of this run's 377 (pytest's
# count) on a 2-core machine, and CI's whole run 18 minutes (its budget is 20).
RECONSTRUCTION_ENGINE = "vkfft" if "vkfft" in DEVICE_ENGINES else "(reikna and not unpacked)"
RECONSTRUCTIONS = ("test_reconstruction_matches_numpy", "test_admm_reconstruction_matches_numpy")
FFT_ENGINES_UNDER_RACE_CHECKS = ("((reikna or vkfft) and not reconstruction and not read_only_memory) or transformed"
                                 f" or ({RECONSTRUCTION_ENGINE} and ({' or '.join(RECONSTRUCTIONS)}))")
PLATFORMS = [
    Platform("pocl", "pocl", "Portable Computing Language", engines=DEVICE_ENGINES),
    Platform("intel", "intel", "Intel(R) OpenCL", engines=DEVICE_ENGINES),
    Platform("oclgrind", "oclgrind", "Oclgrind", TINY + ("--cl-keep-buffers", "-k", NOT_UNDER_ALL_CHECKS), OCLGRIND_ALL),
    Platform("oclgrind-fft", "oclgrind", "Oclgrind", TINY + ("-k", FFT_ENGINES_UNDER_RACE_CHECKS), OCLGRIND,
             FFT_CHECKED_ENGINES, RECONSTRUCTIONS),
]


def platform_environment(platform: Platform, folder: Path) -> dict[str, str]:
    """The variables that list ``platform`` (skip when it is not installed, or when it is the device this process's
    tests/test_parity.py runs on; fail when installed but not listed)."""
    if platform.implementation == "pocl" and default_platform() == platform.platform:
        pytest.skip("PoCL is this process's device: tests/test_parity.py runs its parity (both paths)")
    if platform.implementation == "pocl" and (reason := pocl_build_failure()):
        pytest.skip(f"PoCL cannot compile on this machine's CPU ({reason}); the other platforms run the parity")
    if platform.implementation != "pocl" and cl_icd.library(platform.implementation) is None:
        pytest.skip(f"{platform.platform} is not installed: {cl_icd.INSTALL[platform.implementation]}")
    env = {**os.environ, **cl_icd.vendors_environment(folder), "PYOPENCL_CTX": platform.platform, **platform.env}
    listed = subprocess.run([sys.executable, "-c", "import pyopencl as cl; print([p.name for p in cl.get_platforms()])"],
                            env=env, capture_output=True, text=True, timeout=120)
    if platform.platform not in listed.stdout:
        if platform.implementation == "pocl":
            pytest.skip(f"PoCL is not installed: pip install 'clsdcam[pocl]' ({listed.stdout.strip()})")
        pytest.fail(f"{platform.platform} is installed but not listed: {listed.stdout} {listed.stderr[-2000:]}")
    return env


def default_platform() -> str | None:
    """The platform of the device tests/test_parity.py picks in this process (None without one)."""
    from clsdcam.backends import cl_devices
    from clsdcam.errors import InputError

    try:
        return cl_devices.choose_device().platform.name.strip()
    except InputError:
        return None


def code_paths(platform: Platform) -> str:
    """The device path on every platform; on Intel's runtime both paths when this process has no OpenCL device of
    its own (PoCL cannot compile on this CPU), so that the host path's parity is still checked somewhere."""
    return "all" if platform.implementation == "intel" and default_platform() is None else "device"


def pocl_build_failure() -> str:
    """Why this process's PoCL device cannot build a kernel ("" when it can, or when PoCL is not listed here)."""
    from clsdcam.backends import cl_devices
    from clsdcam.errors import InputError

    try:
        pocl = [d for p, d in cl_devices.all_devices() if p.name.strip() == "Portable Computing Language"]
    except InputError:
        return ""
    return cl_devices.build_failure(pocl[0]) if pocl else ""


def outcomes(junit: Path) -> dict[str, str]:
    """test name -> passed, skipped or failed, from a JUnit XML report."""
    result = {}
    for case in ElementTree.parse(junit).iter("testcase"):
        kinds = {child.tag for child in case}
        result[case.get("name")] = ("failed" if kinds & {"failure", "error"} else
                                    "skipped" if "skipped" in kinds else "passed")
    return result


def parameters(test_name: str) -> list[str]:
    """A test's parameter ids: ``test_fft[fft2-float32-reikna-unpacked]`` -> fft2, float32, reikna-unpacked."""
    inside = test_name.partition("[")[2].rstrip("]").replace("reikna-unpacked", "reikna_unpacked")
    return [part.replace("_unpacked", "-unpacked") for part in inside.split("-")]


@pytest.mark.timeout(PORTABILITY_TIMEOUT)
@pytest.mark.parametrize("platform", PLATFORMS, ids=lambda p: p.name)
def test_parity_on_the_device_path(platform, tmp_path):
    env = platform_environment(platform, tmp_path / "vendors")
    junit, log = tmp_path / "parity.xml", tmp_path / "oclgrind.log"
    command = [sys.executable, "-m", "pytest", "-q", "-rs", "-p", "no:cacheprovider", "-W", "ignore",
               str(REPO / "tests" / "test_parity.py"), "--cl-path", code_paths(platform), f"--junitxml={junit}",
               *platform.options]
    done = subprocess.run(command, env={**env, "OCLGRIND_LOG": str(log)}, cwd=REPO, capture_output=True, text=True,
                          timeout=PORTABILITY_TIMEOUT)
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-3000:]
    results = outcomes(junit)
    passed = [name for name, outcome in results.items() if outcome == "passed"]
    assert len(passed) >= 20, done.stdout[-3000:]
    for engine in platform.engines:
        assert any(engine in parameters(name) for name in passed), f"no {engine} test passed"
    for test in platform.tests:
        assert any(name.partition("[")[0] == test for name in passed), f"{test} did not pass"
    reports = log.read_text() if log.exists() else ""
    assert not reports, reports[:6000]
    print(f"{platform.name}: {len(passed)} passed, {sum(o == 'skipped' for o in results.values())} skipped")


def test_the_vendor_folder_lists_the_named_implementations_alone(tmp_path, capsys):
    """``python -m clsdcam.backends.cl_icd DIR intel`` (CI's, where no device compiles in-process) writes Intel's ICD
    file alone, never Oclgrind's; without names, every installed one; an unknown name is one usage line, exit 2."""
    assert cl_icd.main([str(tmp_path / "intel"), "intel"]) == 0
    exports = capsys.readouterr().out
    assert f"export OCL_ICD_VENDORS='{tmp_path / 'intel'}'" in exports
    written = {path.name for path in (tmp_path / "intel").glob("clsdcam-*.icd")}
    assert written == ({"clsdcam-intel.icd"} if cl_icd.library("intel") else set())
    assert ("LD_LIBRARY_PATH" in exports) == bool(cl_icd.library("intel"))

    assert cl_icd.main([str(tmp_path / "all")]) == 0
    assert {path.name for path in (tmp_path / "all").glob("clsdcam-*.icd")} == \
        {f"clsdcam-{name}.icd" for name in cl_icd.INSTALL if cl_icd.library(name)}

    capsys.readouterr()
    assert cl_icd.main([str(tmp_path / "none"), "pocl"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown: pocl" in err
    assert not (tmp_path / "none").exists()
