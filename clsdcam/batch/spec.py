"""What a batch is (:class:`BatchSpec`, everything a worker needs) and what it did (:class:`BatchSummary`)."""
from __future__ import annotations

from dataclasses import dataclass, field

from ..calibration import Preprocessing
from ..errors import InputError
from ..settings import Settings


@dataclass(frozen=True)
class BatchSpec:
    """Everything a worker needs to reconstruct any chunk (picklable)."""

    frames: tuple[str, ...]
    calibration: str
    preprocessing: Preprocessing = Preprocessing()
    settings: Settings = Settings()
    backend: str = "numpy"
    device: str | None = None
    fft: str = "auto"
    path: str = "auto"
    warm_start: bool = True

    def __post_init__(self):
        if self.preprocessing.saturation is not None:
            raise InputError("saturation masks differ from frame to frame: not available in batch (mark the "
                             "sensor's bad pixels with dead_pixels instead)")


@dataclass
class BatchSummary:
    n_frames: int
    computed_frames: int
    failed: list[tuple[int, str]] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0
