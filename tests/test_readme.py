"""The README's Python snippets run as written (in a folder where `clsdcam simulate sim/` has run)."""
import re
from pathlib import Path

import pytest

from clsdcam.cli import main

README = Path(__file__).resolve().parents[1] / "README.md"


def python_snippets() -> list[str]:
    return re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


@pytest.mark.parametrize("snippet", python_snippets())
def test_readme_python_runs(snippet, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["simulate", "sim", "--size", "32x40", "--bands", "4", "--scene", "leds"]) == 0
    exec(compile(snippet, "README.md", "exec"), {})


def test_the_readme_has_python_and_is_short():
    assert python_snippets() and len(README.read_text(encoding="utf-8").splitlines()) <= 300
