"""The structure the code relies on (docs/architecture.md): layers without cycles, small modules, a backend
contract both backends keep, and a command line that builds its parser without heavy imports."""
import ast
import inspect
import subprocess
import sys
import time
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


def imports(path: Path, known: set[str]) -> set[str]:
    """clsdcam modules imported anywhere in ``path`` (module level or inside functions)."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found |= {alias.name for alias in node.names if alias.name in known}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([node.module] if node.module else []))
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


def test_no_module_above_400_lines():
    long = {name: n for name, path in modules().items() if (n := len(path.read_text().splitlines())) > MAX_LINES}
    assert not long, long


SOLVE_CORE = ("clsdcam.driver", "clsdcam.checkpoints", "clsdcam.algorithms", "clsdcam.phases", "clsdcam.space_policy",
              "clsdcam.spaces", "clsdcam.auto_weights", "clsdcam.state", "clsdcam.tracker", "clsdcam.problem",
              "clsdcam.subspace")


def reachable(edges: dict[str, set[str]], start: str) -> set[str]:
    seen, stack = set(), [start]
    while stack:
        for target in edges[stack.pop()] - seen:
            seen.add(target)
            stack.append(target)
    return seen


def test_the_loop_the_policy_and_the_spaces_never_reach_the_solver():
    """No module of the loop, the policy or the spaces imports clsdcam.solver, directly or through another, or
    takes a parameter named ``solver``."""
    edges = graph()
    core = [name for name in edges if name.startswith(SOLVE_CORE)]
    assert len(core) >= len(SOLVE_CORE)
    for name in core:
        assert "clsdcam.solver" not in reachable(edges, name), name
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


HEAVY = ("scipy", "h5py", "matplotlib", "pyopencl", "dask", "distributed", "clsdcam.solver", "clsdcam.sim",
         "clsdcam.analysis", "clsdcam.batch")


def test_building_the_parser_imports_nothing_heavy():
    code = ("import sys; from clsdcam.cli.options import build_parser; build_parser(); "
            f"print([m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_help_is_quick():
    """``clsdcam --help`` ≤ 0.3 s is the goal (0.12 s measured on the 2-core CI machine); the bound here is
    generous, for loaded machines: the best of three runs under 1 s."""
    seconds = []
    for _ in range(3):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "clsdcam", "--help"], capture_output=True, check=True)
        seconds.append(time.perf_counter() - start)
    assert min(seconds) < 1.0, seconds
