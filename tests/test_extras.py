"""The optional extras (clsdcam.extras, pyproject's optional-dependencies): without one, each use that needs it says
which install to run (one line, exit 2, nothing written); the core runs the demo and draws its pictures with none;
every package clsdcam imports is a core dependency or an extra's, and the test extra installs every extra."""
import ast
import importlib.metadata
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from clsdcam.cli import main
from clsdcam.errors import InputError
from clsdcam.extras import NEEDS, require
from clsdcam.io import write_cube
from clsdcam.napari_reader import cube_layer
from clsdcam.sim import band_wavelengths
from clsdcam.sim.kinds import make_kind

REPO = Path(__file__).resolve().parents[1]
PROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["project"]
EXTRAS = PROJECT["optional-dependencies"]
MACHINE_EXTRAS = {"vkfft", "intel"}       # what one machine's OpenCL offers: .ci/run adds them beside the test extra
ELSEWHERE = {"pyvkfft", "numba"}          # the vkfft and jit extras' modules: the package runs without them
EXTRA_MODULES = sorted({module for _, modules in NEEDS.values() for module in modules})


def without(monkeypatch, *modules):
    """``import m`` raises ImportError for each of ``modules``, as when it is not installed."""
    for module in modules:
        monkeypatch.setitem(sys.modules, module, None)


def says_install(capsys, use: str, extra: str, module: str):
    """The command said nothing but the one line naming ``use``, the extra, its install command and ``module``."""
    assert capsys.readouterr() == ("", f"clsdcam: error: {use} needs the {extra} extra: pip install "
                                       f"'clsdcam[{extra}]' (not installed: {module})\n")


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("video")
    assert main(["simulate", str(out), "--frames", "2", "--size", "16x20", "--bands", "4", "--scene", "leds"]) == 0
    return out


@pytest.mark.parametrize("use", NEEDS)
def test_require_names_the_extra_and_its_install(use, monkeypatch):
    extra, modules = NEEDS[use]
    require(use)
    without(monkeypatch, modules[-1])
    with pytest.raises(InputError, match=rf"^{use} needs the {extra} extra: pip install 'clsdcam\[{extra}\]' "
                                         rf"\(not installed: {modules[-1]}\)$"):
        require(use)


@pytest.mark.parametrize("module", NEEDS["batch"][1])
def test_batch_without_the_video_extra_exits_2_and_writes_nothing(module, video, tmp_path, capsys, monkeypatch):
    without(monkeypatch, module)
    assert main(["batch", str(video / "frames.npy"), "--calibration", str(video / "calibration.h5"),
                 "-o", str(tmp_path / "cubes.h5"), "--workers", "0", "--iters", "2", "--quiet"]) == 2
    says_install(capsys, "batch", "video", module)
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize("name, module", [("cube.nc", "xarray"), ("cube.nc", "h5netcdf"), ("cube.hdr", "spectral")])
def test_export_without_the_export_extra_exits_2_and_writes_nothing(name, module, tmp_path, capsys, monkeypatch):
    source = write_cube(tmp_path / "cube.h5", [[[1.0]], [[2.0]]], [500.0, 600.0])
    out = tmp_path / "out"
    without(monkeypatch, module)
    assert main(["export", str(source), "-o", str(out / name)]) == 2
    says_install(capsys, "NetCDF export" if name.endswith(".nc") else "ENVI export", "export", module)
    assert not out.exists()


def test_the_other_formats_need_no_extra(tmp_path, monkeypatch):
    source = write_cube(tmp_path / "cube.h5", [[[1.0]], [[2.0]]], [500.0, 600.0])
    without(monkeypatch, *EXTRA_MODULES)
    for name in ("cube.tif", "cube.png"):
        assert main(["export", str(source), "-o", str(tmp_path / name)]) == 0 and (tmp_path / name).is_file()


def test_a_batch_output_in_the_napari_reader_without_dask_says_so_and_a_cube_still_opens(video, monkeypatch):
    without(monkeypatch, "dask")
    with pytest.raises(InputError, match=r"reading a batch output's frames lazily needs the video extra"):
        cube_layer(video / "truth.h5")
    cube = write_cube(video / "one.h5", [[[1.0]], [[2.0]]], [500.0, 600.0])
    assert cube_layer(cube)[0].shape == (2, 1, 1)


def test_the_natural_scene_kind_without_scikit_image_says_so(monkeypatch):
    without(monkeypatch, "skimage")
    with pytest.raises(InputError, match=r"the natural scene kind needs the video extra"):
        make_kind("natural", (24, 32), band_wavelengths(4), 0)
    assert make_kind("piecewise", (24, 32), band_wavelengths(4), 0).shape == (4, 24, 32)


def test_the_demo_draws_its_pictures_with_no_extra_installed(tmp_path):
    """The core install's job, in a process where every extra's module (and colour-science, pandas) is missing."""
    blocked = [*EXTRA_MODULES, "colour", "pandas"]
    code = (f"import sys; sys.modules.update(dict.fromkeys({blocked!r})); from clsdcam.cli import main; "
            f"sys.exit(main(['demo', {str(tmp_path / 'demo')!r}, '--size', '40x48', '--bands', '6', '--iters', '5', "
            "'--quiet']))")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, timeout=300)
    assert {"cube_falsecolour.png", "cube_spectra.png", "cube.h5"} <= {p.name for p in (tmp_path / "demo").iterdir()}


def distributions(requirement: str) -> set[str]:
    """The distribution ``requirement`` names and those its [extras] add (read from its installed metadata)."""
    parsed = Requirement(requirement)
    added = {Requirement(line) for line in importlib.metadata.requires(parsed.name) or []}
    return {canonicalize_name(parsed.name)} | {canonicalize_name(r.name) for r in added if r.marker and any(
        r.marker.evaluate({"extra": extra}) for extra in parsed.extras)}


def provider(module: str) -> str:
    """The installed distribution that provides the top-level ``module``."""
    return canonicalize_name(importlib.metadata.packages_distributions()[module][0])


def test_each_use_names_an_extra_that_installs_its_modules():
    for use, (extra, modules) in NEEDS.items():
        provided = set().union(*map(distributions, EXTRAS[extra]))
        assert {provider(m) for m in modules} <= provided, f"{use}: [{extra}] does not install all of {modules}"


def test_the_test_extra_installs_every_extra_but_the_machines():
    (own,) = [Requirement(r) for r in EXTRAS["test"] if Requirement(r).name == PROJECT["name"]]
    assert own.extras == set(EXTRAS) - MACHINE_EXTRAS - {"test"}


def imported_packages() -> set[str]:
    """The top-level names of the third-party modules imported anywhere in clsdcam (module level or inside a
    function)."""
    found = set()
    for path in (REPO / "clsdcam").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                found |= {alias.name.split(".")[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and not node.level:
                found.add(node.module.split(".")[0])
    return found - set(sys.stdlib_module_names) - {"clsdcam"}


def test_every_imported_package_is_a_core_dependency_or_an_extras():
    core = {canonicalize_name(Requirement(r).name) for r in PROJECT["dependencies"]}
    undeclared = {m for m in imported_packages() - set(EXTRA_MODULES) - ELSEWHERE if provider(m) not in core}
    assert not undeclared, f"imported, but neither a core dependency nor in clsdcam.extras.NEEDS: {undeclared}"
