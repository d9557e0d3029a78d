"""The project's own set-up promises: README commands, CI script, kernels inside the wheel."""
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent


def readme_commands() -> list[str]:
    """The shell lines of the README's first code block."""
    text = (REPO / "README.md").read_text()
    block = text.split("```bash\n", 1)[1].split("```", 1)[0]
    return [line for line in block.splitlines() if line.strip()]


def test_readme_opens_with_exactly_two_setup_commands():
    commands = readme_commands()
    assert len(commands) == 2
    assert "clsdcam demo" in commands[0] and "pytest" in commands[1]
    assert (REPO / "README.md").read_text().startswith("# clsdcam\n")


def test_ci_runs_the_readme_test_command():
    ci_lines = (REPO / ".ci" / "run").read_text().splitlines()
    assert readme_commands()[1] in ci_lines


def test_a_checkout_on_pythonpath_runs_its_own_kernels_not_the_editable_installs(tmp_path):
    """An A/B of two commits puts the other checkout on PYTHONPATH: its Python and its kernels/ run, not the
    kernels the editable install maps ``clsdcam.kernels`` to."""
    other = tmp_path / "other"
    shutil.copytree(REPO / "clsdcam", other / "clsdcam", ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copytree(REPO / "kernels", other / "kernels")
    code = "import clsdcam.backends.cl_program as p; print(p.__file__); print(p.kernel_dir())"
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(other)},
                         capture_output=True, text=True, check=True).stdout.split()
    assert out == [str(other / "clsdcam" / "backends" / "cl_program.py"), str(other / "kernels")]


def test_wheel_ships_every_kernel_and_the_colour_table_and_the_installed_package_finds_them(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(REPO)],
                   check=True, capture_output=True, timeout=600)
    (wheel,) = tmp_path.glob("clsdcam-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    sources = sorted(p.name for p in (REPO / "kernels").glob("*.cl"))
    assert sources, "no kernels/*.cl in the source tree"
    assert {f"clsdcam/kernels/{name}" for name in sources} <= names
    assert {"clsdcam/kernels/__init__.py", "clsdcam/cie1931_2deg.csv"} <= names
    site = tmp_path / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=600)
    code = ("import clsdcam, clsdcam.backends.cl_program as p, clsdcam.colorimetry as c; "
            "print(clsdcam.__file__); print(p.kernel_dir()); print(len(p.source())); "
            "print(len(c.colour_matching_functions()[0]))")
    out = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, env={**os.environ, "PYTHONPATH": str(site)},
                         capture_output=True, text=True, check=True).stdout.split()
    assert out[0].startswith(str(site)) and out[1].startswith(str(site)), out
    assert int(out[2]) > 1000 and out[3] == "471"

