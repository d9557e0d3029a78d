"""What a batch is (:class:`BatchSpec`, everything a worker needs) and what it did (:class:`BatchSummary`, or
:class:`BatchInterrupted` when Ctrl-C stopped it with some frames kept)."""
from __future__ import annotations

from dataclasses import dataclass, field

from ..camera.calibration import Preprocessing
from ..errors import InputError
from ..solve.settings import COLD_ITERS, Settings


@dataclass(frozen=True)
class BatchSpec:
    """Everything a worker needs to reconstruct any chunk (picklable). ``settings.budget`` is the budget of a
    warm-started frame, ``cold_iters`` (None: max(COLD_ITERS, settings.budget)) that of a cold start (a chunk's
    first frame, a frame after a failed one); without ``warm_start`` every frame gets ``settings.budget``. With
    ``--iters auto`` every frame also stops when converged (:mod:`clsdcam.solve.convergence`)."""

    frames: tuple[str, ...]
    calibration: str
    preprocessing: Preprocessing = Preprocessing()
    settings: Settings = Settings()
    backend: str = "numpy"
    device: str | None = None
    fft: str = "auto"
    path: str = "auto"
    warm_start: bool = True
    cold_iters: int | None = None

    def __post_init__(self):
        if self.preprocessing.saturation is not None:
            raise InputError("saturation masks differ from frame to frame: not available in batch (mark the "
                             "sensor's bad pixels with dead_pixels instead)")

    def budget(self, warm: bool) -> int:
        """Iterations of a frame at most: ``settings.budget`` when warm-started (or without warm starts at all), else
        the cold budget."""
        if warm or not self.warm_start:
            return self.settings.budget
        return self.cold_iters or max(COLD_ITERS, self.settings.budget)


@dataclass
class BatchSummary:
    n_frames: int
    computed_frames: int
    failed: list[tuple[int, str]] = field(default_factory=list)
    seconds: float = 0.0
    layout: str = ""  # where the frames ran, e.g. "2 workers × 1 thread on 2 cores"
    per_frame: dict = field(default_factory=dict)   # the output's per-frame records: iterations, warm, error, …
    accuracy: dict = field(default_factory=dict)    # against a truth: {figure: per-frame values} (else empty)

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C after ``kept`` of the ``n_frames`` frames were finished in ``parts``: they are kept, and running
    the same batch again computes only the others."""

    def __init__(self, kept: int, n_frames: int, parts):
        super().__init__(f"interrupted; {kept} of {n_frames} frames kept in {parts}/ — run the same command "
                         "again to finish")
        self.kept, self.n_frames, self.parts = kept, n_frames, parts
