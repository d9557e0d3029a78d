"""The real 2-D transforms on the host as their two 1-D passes: the inverse's first in place on a spent spectrum, and
both pruned to the sensor window, which sits at the field's origin.

    irfft2(X, s=(Hp, Wp)) = irfft(ifft(X, n=Hp, axis=−2), n=Wp, axis=−1)

Called one after the other, the column pass can run in place on a spectrum the caller no longer needs (ADMM's c-step,
FISTA's adjoint). On a 64-band field, one thread, that took 0.82× the time of pocketfft's own ``irfft2`` (SciPy 1.17)
at 256×320 and 0.40× at 640×896, where ``irfft2`` told it may overwrite its input took 0.98× and 0.90×; the result
the same bit for bit at 256×320 and to float32's rounding at 640×896 (5.4·10⁻⁷ of values up to 1). In a solve the
saving is smaller (docs/benchmarks.md, "The inverse transform in place"). Where the spectrum must be kept, the two
passes took 1.03× and 0.84× irfft2's time. The forward transform of a whole field stays pocketfft's ``rfft2``.

Pruned (:func:`rfft2_of_window`, :func:`irfft2_to_window`): a field that is zero outside an (H, W) window at the origin
needs its row pass on the window's H rows only (the rest of each row is zero padding, done by ``n=``); a field of which
only the window is wanted needs the inverse's row pass on those H rows only. With H, W half the field's, in ADMM's
solves on one thread, they took 0.84–0.87× and 0.70–0.77× the whole transforms' time at 256×320 (64 bands), 0.60–0.67×
and 0.78–0.83× at 640×896 (docs/benchmarks.md, "ADMM's data split on the window").
"""
from __future__ import annotations

import scipy.fft


def irfft2(spectrum, shape, workers: int = 1, overwrite: bool = False):
    """The real (…, Hp, Wp) inverse of a half spectrum (…, Hp, Wp//2 + 1), 1/N normalised, as ``scipy.fft.irfft2``
    with ``s=shape``: the inverse complex transform along y (in place on ``spectrum`` when ``overwrite``), then the
    inverse real transform along x to ``shape[1]`` points."""
    hp, wp = shape
    columns = scipy.fft.ifft(spectrum, n=hp, axis=-2, workers=workers, overwrite_x=overwrite)
    return scipy.fft.irfft(columns, n=wp, axis=-1, workers=workers, overwrite_x=True)


def rfft2_of_window(window, field_shape, workers: int = 1):
    """rfft2 of the (…, H, W) ``window`` zero-padded to ``field_shape`` at the origin: the row pass on its H rows (to
    Wp points), then the column pass (to Hp points)."""
    hp, wp = field_shape
    rows = scipy.fft.rfft(window, n=wp, axis=-1, workers=workers)
    return scipy.fft.fft(rows, n=hp, axis=-2, workers=workers, overwrite_x=True)


def irfft2_to_window(spectrum, field_shape, window_shape, workers: int = 1, overwrite: bool = False):
    """The (…, H, W) window at the origin of irfft2(``spectrum``, ``field_shape``): the column pass (in place on
    ``spectrum`` when ``overwrite``), then the row pass on the window's H rows only."""
    (hp, wp), (h, w) = field_shape, window_shape
    columns = scipy.fft.ifft(spectrum, n=hp, axis=-2, workers=workers, overwrite_x=overwrite)[..., :h, :]
    return scipy.fft.irfft(columns, n=wp, axis=-1, workers=workers)[..., :w]
