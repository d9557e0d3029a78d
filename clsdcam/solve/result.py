"""What a solve returns (:class:`Result`): the cube in the calibration's units, its wavelengths, the history, the
attributes that say how it was made, and what a video's next frame starts from."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .state import SolverState


@dataclass
class Result:
    cube: np.ndarray               # (K, H, W) float32, the sensor window
    wavelengths: np.ndarray        # (K,)
    history: list[dict]
    attrs: dict
    full_field: np.ndarray | None = None
    snapshots: dict[int, np.ndarray] = field(default_factory=dict)  # iteration -> (K, H, W) cube, as ``cube`` is
    state: SolverState | None = None     # what the next frame of a stream can start from (clsdcam.solve.state)

    @property
    def iterations(self) -> int:
        return int(self.attrs["iterations"])

    @property
    def stop_reason(self) -> str:
        return str(self.attrs["stop_reason"])

    def save(self, path):
        """Write the cube, wavelengths, history and attributes to HDF5, atomically."""
        from ..io import write_cube

        write_cube(path, self.cube, self.wavelengths, self.history, self.attrs, full_field=self.full_field)
