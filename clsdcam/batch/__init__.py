"""Many frames: warm-started streams, spread over Dask distributed workers.

One module a part: :mod:`.spec` (what a batch is), :mod:`.frames` (where its frames come
from), :mod:`.stream` (a chunk of frames as one warm-started stream, and the per-process
solver cache), :mod:`.motion` (the warm start's drift prediction), :mod:`.parts` (part files,
resume, the output file), :mod:`.workers` (processes × threads, the Dask client), :mod:`.distribute`
(chunks on Dask or in this process), :mod:`.truth` (the accuracy against a simulated video's truth). The names
the rest of clsdcam uses are importable from here.
"""
from .distribute import run_batch
from .frames import FrameSource
from .motion import predict
from .parts import chunk_bounds, parts_dir
from .spec import BatchInterrupted, BatchSpec, BatchSummary
from .stream import solve_chunk

__all__ = ["BatchInterrupted", "BatchSpec", "BatchSummary", "FrameSource", "chunk_bounds", "parts_dir", "predict",
           "run_batch", "solve_chunk"]
