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
