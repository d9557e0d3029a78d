"""``batch --truth``: a batch's accuracy against the true cubes of a simulated video (the ``truth.h5`` of
``clsdcam simulate --frames``: ``cubes`` (N, K, H, W)).

Checked before any work (:class:`TruthVideo`): N must be the batch's frame count, K × H × W the cube each frame
is reconstructed into (the calibration's bands after preprocessing, the measurement's window), and the
wavelengths, when the file holds them, the calibration's. Scored as the output is assembled
(:meth:`TruthVideo.score`): frame i's :func:`clsdcam.metrics.accuracy` of the written cube against true cube i,
one frame of each in memory at a time.
"""
from __future__ import annotations

import numpy as np

from ..camera.calibration import Calibration
from ..errors import InputError, shape_text
from ..io import existing_file, first_line, wavelength_key
from ..metrics import accuracy


class TruthVideo:
    """The true cubes of a batch's ``n_frames`` frames, reconstructed with ``calibration`` (the prepared one,
    :func:`clsdcam.batch.stream.frame_calibration`); InputError (one line) when the file does not match."""

    def __init__(self, path, n_frames: int, calibration: Calibration):
        self.path = existing_file(path, "--truth")
        shape, wavelengths = self._layout()
        expected = (n_frames, calibration.n_bands) + tuple(calibration.shape)
        if shape != expected:
            raise InputError(f"--truth {self.path}: {mismatch(shape, expected)} (true cubes {shape_text(shape)}, "
                             f"the batch's {shape_text(expected)}: frames × bands × height × width)")
        if wavelengths is not None and not np.allclose(wavelengths, calibration.wavelengths):
            raise InputError(f"--truth {self.path}: its wavelengths {wavelengths.min():g}–{wavelengths.max():g} nm "
                             f"are not the calibration's ({np.min(calibration.wavelengths):g}–"
                             f"{np.max(calibration.wavelengths):g} nm)")

    def _layout(self) -> tuple[tuple[int, ...], np.ndarray | None]:
        """(the shape of ``cubes``, the wavelengths or None when the file names none)."""
        import h5py

        try:
            with h5py.File(self.path, "r") as f:
                if not isinstance(f.get("cubes"), h5py.Dataset):
                    raise InputError(f"--truth {self.path}: no dataset 'cubes' (a video's truth.h5, from clsdcam "
                                     f"simulate --frames; found: {', '.join(sorted(f.keys())) or 'none'})")
                key = wavelength_key(f)
                return f["cubes"].shape, f[key][...] if key else None
        except OSError as exc:
            raise InputError(f"--truth {self.path}: not a readable HDF5 file ({first_line(exc)})") from None

    def score(self, cubes) -> dict[str, np.ndarray]:
        """Per frame, :func:`clsdcam.metrics.accuracy` of ``cubes[i]`` against true cube i: {figure: (N,) array}.
        A failed frame's cube is NaN, and so are its figures."""
        import h5py

        with h5py.File(self.path, "r") as f:
            rows = [accuracy(cubes[i], f["cubes"][i]) for i in range(len(cubes))]
        return {name: np.array([row[name] for row in rows]) for name in rows[0]}


def mismatch(shape, expected) -> str:
    """What differs first between a truth's (N, K, H, W) and the batch's, in words."""
    if shape[:1] != expected[:1]:
        return f"{shape[0]} true cubes for {expected[0]} frames"
    if shape[1:2] != expected[1:2]:
        return f"{shape[1]} bands where the calibration gives {expected[1]}"
    return f"true cubes of {shape_text(shape[2:])} pixels for reconstructions of {shape_text(expected[2:])}"
