"""Without pyopencl: clsdcam and the NumPy backend still work, and asking for OpenCL says how to install PoCL."""
import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent

SCRIPT = textwrap.dedent("""
    import sys
    sys.modules["pyopencl"] = None          # import pyopencl now raises ImportError
    import numpy as np
    import clsdcam
    from clsdcam.backends import get_backend
    from clsdcam.errors import InputError
    from clsdcam.camera.model import ForwardModel

    rng = np.random.default_rng(0)
    model = ForwardModel(get_backend("numpy"), rng.random((5, 7)), rng.random((2, 5, 7)))
    b = model.forward(model.embed(rng.random((2, 5, 7))))
    assert b.shape == (5, 7) and model.adjoint(b).shape == model.cube_shape
    try:
        get_backend("opencl")
    except InputError as exc:
        print("InputError:", exc)
    else:
        raise SystemExit("get_backend('opencl') did not raise InputError")
""")


def test_numpy_backend_works_and_opencl_is_an_input_error_without_pyopencl():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=REPO, capture_output=True, text=True,
                          env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "InputError:" in done.stdout and "PoCL" in done.stdout
