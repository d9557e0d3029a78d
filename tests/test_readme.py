"""The README runs as written: its Python snippets (in a folder where `clsdcam simulate sim/` has run), and every
shell command in its ```bash blocks and its inline commands as pasted from the clone after the set-up line, which
makes .venv but does not activate it.

Each command must run from .venv (`.venv/bin/clsdcam`, `.venv/bin/python`, `.venv/bin/pip`, or a tools/ script),
its executable installed by the set-up line or an earlier README command, its options accepted by the real
parser (clsdcam's `build_parser`, a tool's own), and every file it reads present (in ../shared/data, the clone's
neighbour) or written by an earlier README command, or one of the authors' downloads the README links to.
Everything they write lies where git ignores it (`git status` stays clean). The blocks that need neither a download
nor the set-up's demo also run for real, iterations capped, in a git repository that holds the clone's .gitignore.
Every figure of the README (a number with a unit, or of iterations) is checked against the code that produces it.
"""
from __future__ import annotations

import argparse
import contextlib
import glob
import importlib.util
import io
import os
import re
import runpy
import shlex
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path
from unittest import mock

import pytest

from clsdcam.cli import main
from clsdcam.cli.demo import fill_defaults
from clsdcam.cli.options import build_parser
from clsdcam.errors import InputError

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
GUIDE = REPO / "docs" / "guide.md"        # the user guide: its commands run after the README's, in the same walk
SHARED = REPO.parent / "shared"
PYPROJECT = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
VENV = ".venv/bin/"
# The authors' sample data: in neither the clone nor ../shared; the README must link to where they are.
DOWNLOADS = {"calibration.mat": "github.com/Waller-Lab/SpectralDiffuserCam",
             "meas_thordog.png": "github.com/Waller-Lab/SpectralDiffuserCam"}
INPUTS = ("measurement", "frames", "calibration", "truth", "dead_pixels", "dark", "sweep", "wavelengths", "power",
          "exposure", "band_edges", "psf", "cube")     # clsdcam's options (argparse dests) that name files it reads
OUTPUTS = ("output", "png", "outdir", "json")          # ... and those that name what it writes
TOOL_OUTPUTS = ("out", "cache", "json")                # the dests of what a tools/ script writes
FOLDERS = ("outdir", "out", "cache")                   # the output dests that name a folder, not a file or prefix
RUN = {"simulate", "calibrate", "reconstruct", "batch", "export", "show"}   # cheap at the README's sizes
SET_UP = {"python", "pip", *PYPROJECT["project"]["scripts"]}              # what the set-up puts in .venv/bin
CAPS = {"iters": "--iters", "cold_iters": "--cold-iters"}                  # capped at 3 iterations when run


def readme() -> str:
    """The README, then the user guide: the documents whose commands run as pasted, in that order."""
    return README.read_text(encoding="utf-8") + "\n" + GUIDE.read_text(encoding="utf-8")


def python_snippets() -> list[str]:
    return re.findall(r"```python\n(.*?)```", readme(), flags=re.S)


def bash_blocks() -> list[list[list[str]]]:
    """Each ```bash block as its commands, each the words the shell passes (continued lines joined, comments
    dropped, `&&` chains split)."""
    return [shell_commands(block) for block in re.findall(r"```bash\n(.*?)```", readme(), flags=re.S)]


def shell_commands(text: str) -> list[list[str]]:
    commands = []
    for line in text.replace("\\\n", " ").splitlines():
        words = shlex.split(line, comments=True)
        while words:
            cut = words.index("&&") if "&&" in words else len(words)
            commands.append(words[:cut])
            words = words[cut + 1:]
    return [command for command in commands if command]


def inline_commands() -> list[list[str]]:
    """The inline code spans of the prose that are shell commands: `pip`, `python`, a tools/ script or a program
    of .venv, with arguments (not a template with "…"). (`clsdcam …` in the prose and tables names a command;
    the README says it stands for `.venv/bin/clsdcam …`.)"""
    prose = re.sub(r"```.*?```", "", readme(), flags=re.S)
    commands = []
    for span in re.findall(r"`([^`]+)`", prose):
        words = without_assignments(shlex.split(span))
        program = re.match(rf"{re.escape(VENV)}|(pip3?|python3?|tools/\S+)$", words[0]) if words else None
        if program and len(words) > 1 and "…" not in span:
            commands.append(words)
    return commands


def without_assignments(words: list[str]) -> list[str]:
    """``VAR=value command …`` → ``command …``."""
    while words and re.fullmatch(r"[A-Za-z_]\w*=\S*", words[0]):
        words = words[1:]
    return words


class Walk:
    """README commands taken in order: what each reads, writes and installs, and what is wrong with it.

    ``downloads``: whether the authors' downloads count as present (not when a block is to run here)."""

    def __init__(self, installed=(), downloads: bool = True):
        self.installed, self.produced, self.downloads = set(installed), set(), downloads
        self.written: list[str] = []       # a file each output makes (one inside each folder)

    def problems(self, words: list[str]) -> list[str]:
        words = without_assignments(words)
        exe, args = words[0], words[1:]
        if exe == "python3" and args == ["-m", "venv", ".venv"]:
            self.installed |= {"python", "pip"}
            return []
        if exe.startswith("tools/") and exe.endswith(".sh"):
            return [] if os.access(REPO / exe, os.X_OK) else [f"{exe}: no such executable in the clone"]
        name = exe.removeprefix(VENV)
        if not exe.startswith(VENV):
            fix = VENV + ("python " + exe if exe.startswith("tools/") else Path(exe).name)
            return [f"`{shlex.join(words)}`: {exe} is not on the PATH after the set-up line (write {fix})"]
        if name not in self.installed:
            return [f"`{shlex.join(words)}`: {exe} is installed by neither the set-up line nor an earlier command"]
        if name in SET_UP and Path(sys.prefix).resolve() == (REPO / ".venv").resolve() and not (REPO / exe).exists():
            return [f"{exe}: missing from the set-up's .venv"]
        check = getattr(self, name, None)
        if check is None:
            return [f"`{shlex.join(words)}`: this test has no check of {exe}'s arguments (add a method)"]
        return [f"`{shlex.join(words)}`: {problem}" for problem in check(args)]

    # ---- one method per executable in .venv/bin: the problems of its arguments ----------------------------
    def clsdcam(self, args: list[str]) -> list[str]:
        try:
            parsed = build_parser().parse_args(args)
        except InputError as exc:                      # argparse's one line
            return [f"clsdcam does not accept it: {exc}"]
        if parsed.command == "demo":                   # its folder depends on --quick
            fill_defaults(parsed)
        problems = [f"reads {path}: {why}" for path in values(parsed, INPUTS) if (why := self.unavailable(str(path)))]
        self.record(parsed, OUTPUTS)
        return problems

    def python(self, args: list[str]) -> list[str]:
        if not args:
            return []
        if args[0] == "-m":
            return [] if importlib.util.find_spec(args[1]) else [f"no module {args[1]} in the venv"]
        if not (args[0].startswith("tools/") and (REPO / args[0]).is_file()):
            return [f"{args[0]}: not a tools/ script of the clone"]
        parsed = tool_parse(args[0], args[1:])
        if isinstance(parsed, str):
            return [parsed]
        self.record(parsed, TOOL_OUTPUTS)
        return []

    def pip(self, args: list[str]) -> list[str]:
        if args[:1] != ["install"]:
            return [f"pip {args[:1]}: only `pip install` is expected"]
        problems = []
        for spec in (a for a in args[1:] if not a.startswith("-")):
            name, extras = re.fullmatch(r"([^\[]+)(?:\[(.*)\])?", spec).groups()
            if name == ".":
                problems += [f"the package has no extra [{e}]" for e in (extras or "").split(",")
                             if e and e not in PYPROJECT["project"]["optional-dependencies"]]
                self.installed |= set(PYPROJECT["project"]["scripts"])
            else:
                self.installed.add(re.match(r"[\w.-]+", name).group())    # a package's own command (napari)
        return problems

    def napari(self, args: list[str]) -> list[str]:
        cli = argparse.ArgumentParser()     # the part of napari's command line the README uses
        cli.add_argument("paths", nargs="*")
        cli.add_argument("--plugin")
        parsed, unknown = cli.parse_known_args(args)
        plugins = set(PYPROJECT["project"]["entry-points"]["napari.manifest"])
        problems = [f"{unknown}: options this test does not know napari to have"] if unknown else []
        if parsed.plugin not in (None, *plugins):
            problems.append(f"--plugin {parsed.plugin}: not this package's napari plugin {plugins}")
        return problems + [f"reads {p}: {why}" for p in parsed.paths if (why := self.unavailable(p))]

    def record(self, parsed: argparse.Namespace, dests):
        """What the parsed command writes (the values of ``dests``): for later commands to read, and to check."""
        for dest in dests:
            for value in values(parsed, [dest]):
                self.produced.add(str(value))
                self.written.append(f"{value}/a-file" if dest in FOLDERS else str(value))

    def unavailable(self, path: str) -> str | None:
        """Why ``path`` (as the command reads it, from the clone) would not be there, or None."""
        path = os.path.normpath(path)
        if path in DOWNLOADS:
            if not self.downloads:
                return "one of the authors' downloads"
            return None if DOWNLOADS[path] in readme() else f"a download the README does not link ({DOWNLOADS[path]})"
        literal = path.split("*")[0].rstrip("/")
        if any(literal == out or literal.startswith((out + "/", out + "_")) for out in self.produced):
            return None
        if path.startswith("../shared/"):
            return None if not SHARED.exists() or glob.glob(str(REPO / path)) else "not in ../shared"
        return "neither in ../shared nor written by an earlier README command"


def values(parsed: argparse.Namespace, dests) -> list:
    """The values of ``dests`` that name files (not flags, numbers or START:STOP:STEP ranges)."""
    found = []
    for dest in dests:
        value = getattr(parsed, dest, None)
        found += value if isinstance(value, list) else [] if value is None else [value]
    return [v for v in found if isinstance(v, (str, Path)) and not re.fullmatch(r"[-+.\deE]+|[^/]*:[^/]*", str(v))]


class Parsed(Exception):
    """Raised by ``ArgumentParser.parse_args`` once it has parsed: a tool stops before any work."""


def tool_parse(script: str, args: list[str]) -> argparse.Namespace | str:
    """What ``python SCRIPT ARGS`` parses to by the tool's own argparse (its ``main(argv)``), doing no work, or
    why it does not get past it."""
    parse_args = argparse.ArgumentParser.parse_args

    def parse_and_stop(parser, argv=None, namespace=None):
        raise Parsed(parse_args(parser, argv, namespace))

    stderr = io.StringIO()
    with mock.patch.object(argparse.ArgumentParser, "parse_args", parse_and_stop), tools_importable(), \
            contextlib.redirect_stderr(stderr):
        try:
            tool(script)["main"](args)
        except Parsed as parsed:
            return parsed.args[0]
        except SystemExit:
            return f"{script} does not accept it: {stderr.getvalue().strip().splitlines()[-1]}"
    return f"{script}: main() returned without parsing its arguments"


def tools_importable():
    """The tools/ folder first on sys.path, as when a tool runs: its scripts import each other."""
    return mock.patch.object(sys, "path", [str(REPO / "tools"), *sys.path])


def tool(script: str) -> dict:
    """The globals of a tools/ script, run as a module (its main() not called)."""
    return runpy.run_path(str(REPO / script), run_name="readme_check")


def git_clone(folder: Path) -> Path:
    """``folder`` made a git repository holding the clone's .gitignore (what `git status` reads)."""
    folder.mkdir(exist_ok=True)
    subprocess.run(["git", "init", "-q", str(folder)], check=True)
    shutil.copy(REPO / ".gitignore", folder / ".gitignore")
    return folder


def untracked(clone: Path) -> list[str]:
    """What `git status` in ``clone`` lists, the .gitignore it was given aside."""
    status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=all"], cwd=clone, check=True,
                            capture_output=True, text=True).stdout
    return [line for line in status.splitlines() if line != "?? .gitignore"]


def runnable_blocks() -> list[list[list[str]]]:
    """The bash blocks after the set-up that run here: clsdcam's cheap commands only, reading nothing from a
    download or from the set-up's demo."""
    return [block for block in bash_blocks()[1:]
            if all(w[0] == VENV + "clsdcam" and w[1] in RUN for w in block)
            and not problems_of(block, Walk(["clsdcam"], downloads=False))]


def problems_of(commands: list[list[str]], walk: Walk) -> list[str]:
    """Each command's problems, judged after the commands before it."""
    return [problem for words in commands for problem in walk.problems(words)]


# ---- the tests ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("snippet", python_snippets())
def test_readme_python_runs_and_leaves_git_status_clean(snippet, tmp_path, monkeypatch):
    """After the README's `clsdcam simulate` (small), in a git repository with the clone's .gitignore."""
    monkeypatch.chdir(git_clone(tmp_path / "clone"))
    simulate = next(words for words in inline_commands() if words[:2] == [VENV + "clsdcam", "simulate"])
    assert main([*simulate[1:], "--size", "32x40", "--bands", "4", "--scene", "leds"]) == 0
    exec(compile(snippet, "README.md", "exec"), {})
    assert not untracked(Path.cwd())


def test_the_readme_has_python_and_is_short():
    """A newcomer's page: at most about 150 lines, with the Python snippet; figures and history live in docs/."""
    assert python_snippets() and len(README.read_text(encoding="utf-8").splitlines()) <= 150


def test_every_readme_command_runs_as_pasted_after_the_set_up_line():
    blocks = bash_blocks()
    assert [" ".join(c[:2]) for c in blocks[0]][:2] == ["python3 -m", VENV + "pip install"], "the set-up block first"
    walk = Walk()
    problems = problems_of([words for block in blocks for words in block] + inline_commands(), walk)
    assert not problems, "\n".join(problems)
    assert {"clsdcam", "python", "pip"} <= walk.installed and sum(map(len, blocks)) > 6


def test_everything_the_readme_commands_write_is_ignored_by_git(tmp_path):
    """`git status` in a clone after every README command: each file they write made, none listed."""
    walk = Walk()
    problems_of([words for block in bash_blocks() for words in block] + inline_commands(), walk)
    clone = git_clone(tmp_path / "clone")
    for path in walk.written:
        (clone / path).parent.mkdir(parents=True, exist_ok=True)
        (clone / path).touch()
    assert len(walk.written) > 10 and not untracked(clone)


FIGURE = r"\d[\d.,]*\s?(?:%|dB|°|×(?!\d)|ms\b|s\b|minutes?\b|frames/s|[MG]iB|(?:\w+ )?iterations\b)"


def test_every_figure_of_the_readme_is_the_codes():
    """The README's figures are those of the code that produces them (the demo's camera, the automatic stop,
    bench_converged's reference), and it has no other (a measured figure lives in docs/ with its command)."""
    from clsdcam.camera.prototype import N_BANDS, SENSOR_SHAPE, SPECTRAL_RANGE
    from clsdcam.sim.filters import TILE
    from clsdcam.solve.auto_weights import POINTS_IN_GOOD_LIGHT_STOP
    from clsdcam.solve.settings import AUTO_CAP, CONVERGE, CONVERGE_WIDE

    good_light = CONVERGE * POINTS_IN_GOOD_LIGHT_STOP
    with tools_importable():
        reference = tool("tools/bench_converged.py")["TODAY"]
    low, high = SPECTRAL_RANGE
    claims = [f"{TILE}×{TILE} spectral filter array, {N_BANDS} bands over {low:g}–{high:g} nm, "
              f"{SENSOR_SHAPE[0]}×{SENSOR_SHAPE[1]} sensor",
              f"within {100 * CONVERGE_WIDE:g} % of that minimiser, {100 * CONVERGE:g} % where the scene is point-like "
              f"({100 * good_light:g} % in good light) or sparse in good light",
              f"`--converge auto`: {CONVERGE_WIDE:g}, or {CONVERGE:g} on point-like scenes ({good_light:g} in good "
              f"light), on sparse ones in good light and where no probe runs, narrower on a few points as a recount "
              f"reads them, at most {AUTO_CAP})",
              f"against {reference['iters']} {reference['algorithm'].upper()} iterations"]
    text = " ".join(re.sub(r"```.*?```", "", README.read_text(encoding="utf-8"), flags=re.S).split())
    assert [claim for claim in claims if claim not in text] == []
    assert [figure for figure in re.findall(FIGURE, text) if not any(figure in claim for claim in claims)] == []


@pytest.mark.parametrize("block", runnable_blocks(), ids=lambda block: block[0][1] + "-" + block[0][2].split("/")[-1])
def test_a_readme_block_runs_for_real(block, tmp_path, monkeypatch):
    """In an empty clone (a git repository with the clone's .gitignore) beside ../shared (a link), each command
    through the CLI, its iterations capped at 3; then `git status` lists nothing."""
    if any("../shared/" in word for words in block for word in words):
        if not SHARED.exists():
            pytest.skip("../shared/data is not present")
        (tmp_path / "shared").symlink_to(SHARED)
    clone = git_clone(tmp_path / "clone")
    monkeypatch.chdir(clone)
    for words in block:
        args = [path for word in words[1:] for path in (sorted(glob.glob(word)) or [word])]
        parsed = build_parser().parse_args(args)
        caps = [a for dest, option in CAPS.items() if hasattr(parsed, dest) for a in (option, "3")]
        assert main(args + caps) == 0, shlex.join(words)
        for out in values(parsed, OUTPUTS):
            assert glob.glob(f"{out}*"), f"{shlex.join(words)} wrote no {out}"
    assert not untracked(clone)


def test_a_readme_block_runs_without_any_data():
    """The simulated sweep needs neither a download nor ../shared: it always runs (in CI too)."""
    assert any(not any("../shared/" in w for words in block for w in words) for block in runnable_blocks())


def test_the_set_up_line_installs_every_package():
    """`pip install .` (the set-up's first line) ships the packages pyproject lists: every one of the source tree."""
    listed = set(PYPROJECT["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "clsdcam").rglob("__init__.py")}
    assert found <= listed, f"packages missing from pyproject.toml: {sorted(found - listed)}"
