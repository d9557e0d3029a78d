"""The stress suite at CI sizes, on every backend: each row must have its required outcome."""
import pytest

from clsdcam.errors import InputError

from .cases import CASES


def available_backends() -> list[str]:
    """numpy, plus opencl when a driver and a device are present."""
    from clsdcam.backends import get_backend

    try:
        get_backend("opencl")
    except InputError:
        return ["numpy"]
    return ["numpy", "opencl"]


@pytest.mark.stress
@pytest.mark.parametrize("backend", available_backends())
@pytest.mark.parametrize("case", sorted(CASES))
def test_stress_case(case, backend):
    rows = CASES[case](backend, "float32", quick=True)
    failed = [r for r in rows if not r.passed]
    assert rows and not failed, failed
