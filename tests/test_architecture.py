"""The structure the code relies on (docs/architecture.md): layers without cycles, small modules, a backend
contract both backends keep, and a command line that builds its parser without heavy imports."""
import ast
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

from clsdcam.backends.base import (FUSIONS, MAX_MATH, Backend, Fusions, Math, Platform, protocol_attributes,
                                   protocol_members)
from clsdcam.backends.numpy import NumpyBackend

PACKAGE = Path(__file__).resolve().parents[1] / "clsdcam"
MAX_LINES = 400


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {module_name(p): p for p in PACKAGE.rglob("*.py")}


def package_of(path: Path) -> str:
    name = module_name(path)
    return name if path.name == "__init__.py" else name.rsplit(".", 1)[0]


def source_module(node: ast.ImportFrom, package: str) -> str:
    """The absolute module a ``from … import`` in ``package`` reads from (relative imports resolved)."""
    if not node.level:
        return node.module or ""
    anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
    return ".".join(anchor + ([node.module] if node.module else []))


def imports(path: Path, known: set[str]) -> set[str]:
    """clsdcam modules imported anywhere in ``path`` (module level or inside functions)."""
    name, package = module_name(path), package_of(path)
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name in known}
        elif isinstance(node, ast.ImportFrom):
            base = source_module(node, package)
            for alias in node.names:
                candidate = f"{base}.{alias.name}"
                found.add(candidate if candidate in known else base)
    return {m for m in found if m in known and m != name}


def graph() -> dict[str, set[str]]:
    known = modules()
    return {name: imports(path, set(known)) for name, path in known.items()}


def test_no_import_cycle():
    edges, state, cycles = graph(), {}, []

    def visit(node, stack):
        state[node] = "open"
        for target in sorted(edges[node]):
            if state.get(target) == "open":
                cycles.append(stack[stack.index(target):] + [target])
            elif target not in state:
                visit(target, stack + [target])
        state[node] = "done"

    for node in sorted(edges):
        if node not in state:
            visit(node, [node])
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_backends_import_nothing_above_them():
    for name, targets in graph().items():
        if name.startswith("clsdcam.backends"):
            above = {t for t in targets if not t.startswith("clsdcam.backends") and t != "clsdcam.errors"}
            assert not above, f"{name} imports {sorted(above)}"


def imported_names(path: Path, known: set[str]) -> list[tuple[str, str]]:
    """(module, name) for each ``from <clsdcam module> import name`` in ``path`` (relative or absolute)."""
    package = package_of(path)
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = source_module(node, package)
            if base in known:
                found += [(base, alias.name) for alias in node.names]
    return found


def test_no_private_name_is_imported_across_modules():
    """A name with a leading underscore stays in its module: nothing imports one from another clsdcam module."""
    known = modules()
    private = [f"{name}: {source}.{imported}" for name, path in known.items()
               for source, imported in imported_names(path, set(known))
               if imported.startswith("_") and not imported.startswith("__")]
    assert not private, private


def test_code_above_the_backends_reaches_them_through_their_package_and_contract():
    """Outside backends/, the only backend modules imported are ``clsdcam.backends`` (its lazy exports) and
    ``clsdcam.backends.base`` (the contract): the rest is the backends' own business."""
    allowed = {"clsdcam.backends", "clsdcam.backends.base"}
    for name, targets in graph().items():
        if not name.startswith("clsdcam.backends"):
            inside = {t for t in targets if t.startswith("clsdcam.backends")} - allowed
            assert not inside, f"{name} imports {sorted(inside)}"


def test_the_calibration_sits_below_the_calibrate_commands():
    """``clsdcam.calibrate`` (from lab frames to a calibration) builds on ``clsdcam.camera.calibration``; nothing runs
    back up: the calibration, and what it imports, reach no calibrate module."""
    edges = graph()
    assert any(t == "clsdcam.camera.calibration" for name, targets in edges.items()
               if name.startswith("clsdcam.calibrate.") for t in targets)
    below = reachable(edges, "clsdcam.camera.calibration") | {"clsdcam.camera.calibration"}
    assert not {m for m in below if m.startswith("clsdcam.calibrate")}, sorted(below)


def test_no_code_name_outside_the_algorithms_and_backends_names_an_algorithm_or_tests_a_backends_name():
    """ADMM lives in algorithms/admm (kernels in kernels/admm.cl, their launches behind backends.base.Programs):
    outside algorithms/ and backends/ no identifier mentions it or its splittings, and no code compares a
    backend's ``name`` with a string."""
    for name, path in modules().items():
        if name.startswith(("clsdcam.algorithms", "clsdcam.backends")):
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        identifiers = {node.id for node in ast.walk(tree) if isinstance(node, ast.Name)} | \
                      {node.attr for node in ast.walk(tree) if isinstance(node, ast.Attribute)} | \
                      {alias.name for node in ast.walk(tree) if isinstance(node, ast.ImportFrom) for alias in node.names} | \
                      {node.name for node in ast.walk(tree) if isinstance(node, (ast.FunctionDef, ast.ClassDef))} | \
                      {node.module or "" for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
        assert not [i for i in identifiers if "admm" in i.lower() or "splitting" in i.lower()], name
        for node in ast.walk(tree):
            if isinstance(node, ast.Compare):
                sides = [node.left, *node.comparators]
                named = any(isinstance(s, ast.Attribute) and s.attr == "name" and
                            "backend" in ast.unparse(s.value).lower() for s in sides)
                assert not (named and any(isinstance(s, ast.Constant) and isinstance(s.value, str) for s in sides)), \
                    f"{name}: {ast.unparse(node)}"


def test_what_an_algorithm_can_do_is_declared_on_its_base_and_read_without_getattr():
    """Every registered algorithm subclasses algorithms.base.Algorithm; no module reads the capabilities (or the
    carry) with getattr or hasattr."""
    from clsdcam.algorithms import ALGORITHMS
    from clsdcam.algorithms.base import Algorithm

    assert all(issubclass(cls, Algorithm) for cls in ALGORITHMS.values())
    capabilities = {"monotone", "field_buffers", "band_space_only", "priors", "carry", "resume", "backends"}
    for name, path in modules().items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in ("getattr", "hasattr"):
                literal = [a.value for a in node.args[1:2] if isinstance(a, ast.Constant)]
                assert not set(literal) & capabilities, f"{name}: {ast.unparse(node)}"


def test_no_algorithm_counts_its_own_transforms():
    """An iteration's FFTs are declared (``Algorithm.transforms``) and put in the record by the driver: no module of
    clsdcam.algorithms, nor a test plug-in, has a ``"transforms"`` key in a dict or a subscript."""
    plug_ins = Path(__file__).parent.glob("*_algorithm.py")
    paths = [path for name, path in modules().items() if name.startswith("clsdcam.algorithms")] + list(plug_ins)
    assert len(paths) > 3
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            keys = node.keys if isinstance(node, ast.Dict) else [node.slice] if isinstance(node, ast.Subscript) else []
            assert not any(isinstance(k, ast.Constant) and k.value == "transforms" for k in keys), path.name


def test_no_module_above_400_lines():
    long = {name: n for name, path in modules().items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, long


SOLVE_CORE = tuple(f"clsdcam.solve.{name}" for name in (
    "driver", "checkpoints", "phases", "space_policy", "spaces", "auto_weights", "state", "tracker", "problem",
    "subspace")) + ("clsdcam.algorithms",)


def reachable(edges: dict[str, set[str]], start: str) -> set[str]:
    seen, stack = set(), [start]
    while stack:
        for target in edges[stack.pop()] - seen:
            seen.add(target)
            stack.append(target)
    return seen


def test_the_loop_the_policy_and_the_spaces_never_reach_the_solver():
    """No module of the loop, the policy or the spaces imports clsdcam.solve.solver, directly or through another, or
    takes a parameter named ``solver``."""
    edges = graph()
    core = [name for name in edges if name.startswith(SOLVE_CORE)]
    assert len(core) >= len(SOLVE_CORE)
    for name in core:
        assert "clsdcam.solve.solver" not in reachable(edges, name), name
        tree = ast.parse(modules()[name].read_text(encoding="utf-8"))
        parameters = {a.arg for node in ast.walk(tree) if isinstance(node, ast.arguments)
                      for a in node.args + node.kwonlyargs}
        assert "solver" not in parameters, name


@pytest.mark.parametrize("implementation", ["numpy", "opencl"])
@pytest.mark.parametrize("contract", [Math, Platform, Fusions], ids=lambda c: c.__name__)
def test_both_backends_keep_the_contract(implementation, contract):
    """Every method of backends/base's Math and Platform exists on both backends with the contract's parameters; so
    do the optional Fusions, which both backends provide."""
    if implementation == "opencl":
        pytest.importorskip("pyopencl")
        from clsdcam.backends.opencl import OpenCLBackend as cls
    else:
        cls = NumpyBackend
    for name in protocol_members(contract):
        expected = list(inspect.signature(getattr(contract, name)).parameters)
        assert list(inspect.signature(getattr(cls, name)).parameters) == expected, name


def test_the_contract_is_narrow():
    """Math has at most MAX_MATH methods; the fusions are apart from it; Backend is Math and Platform; the NumPy
    backend is all three and says everything Platform asks."""
    math, platform, fusions = (set(protocol_members(c)) for c in (Math, Platform, Fusions))
    assert len(math) <= MAX_MATH and fusions == set(FUSIONS)
    assert not math & platform and not (math | platform) & fusions
    assert set(protocol_members(Backend)) == math | platform and "pad" in math and "convolution" in math
    be = NumpyBackend()
    assert isinstance(be, Backend) and isinstance(be, Fusions)
    assert all(hasattr(be, name) for name in protocol_attributes(Platform))


HEAVY = ("scipy", "h5py", "matplotlib", "pyopencl", "dask", "distributed", "numba", "clsdcam.solve.solver",
         "clsdcam.sim", "clsdcam.analysis", "clsdcam.batch")


def test_building_the_parser_imports_nothing_heavy():
    code = ("import sys; from clsdcam.cli.options import build_parser; build_parser(); "
            f"print([m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_help_imports_nothing_heavy():
    """``clsdcam --help`` as users run it (the module, its entry point and the parser) imports none of HEAVY: what
    made help slow was what it imported, which ``-X importtime`` lists whatever the machine's load (the time itself
    is a benchmark's business, not a test's)."""
    run = subprocess.run([sys.executable, "-X", "importtime", "-m", "clsdcam", "--help"], capture_output=True,
                         text=True, check=True)
    imported = {line.split("|")[-1].strip() for line in run.stderr.splitlines() if line.startswith("import time:")}
    assert "clsdcam.cli.options" in imported and "usage" in run.stdout
    assert not {m for m in imported for h in HEAVY if m == h or m.startswith(h + ".")}
