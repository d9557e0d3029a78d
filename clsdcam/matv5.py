"""A small, bounds-checked reader of the numeric arrays in a MATLAB v5 ``.mat`` file.

Why not ``scipy.io.loadmat``: fuzzing showed that about 1 % of damaged v5 files make it
crash the interpreter (segmentation fault in its compiled reader), and a user's corrupt
calibration must give a one-line error instead. Every length here is checked in Python.

Format (MathWorks, "MAT-File Format", v5): a 128-byte header whose last two bytes are the
endian mark ``IM`` (little) or ``MI`` (big), then data elements, each an 8-byte tag
(type, byte count) or a 4-byte "small element" tag, padded to 8 bytes; ``miCOMPRESSED``
elements hold zlib-deflated elements. A numeric ``miMATRIX`` holds, in order: array flags
(class in the low byte, complex bit 0x800), dimensions (int32), name (int8), real part
(any numeric type, column-major). Other classes (cell, struct, char, sparse) are skipped.
"""
from __future__ import annotations

import math
import zlib

import numpy as np

MI_MATRIX, MI_COMPRESSED = 14, 15
MI_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8", 12: "i8", 13: "u8"}
NUMERIC_CLASSES = range(6, 16)   # mxDOUBLE … mxUINT64
COMPLEX_FLAG = 0x800


class MatFormatError(ValueError):
    """The file is not a well-formed MATLAB v5 file (the message says where)."""


def read_mat_v5(data: bytes, max_bytes: int) -> dict[str, np.ndarray]:
    """{name: float64 array} for every real numeric variable; ``max_bytes`` caps decompression."""
    if len(data) < 128:
        raise MatFormatError("shorter than the 128-byte MATLAB header")
    endian = {b"IM": "<", b"MI": ">"}.get(data[126:128])
    if endian is None:
        raise MatFormatError("no endian mark in the MATLAB header")
    variables = {}
    for mdtype, body in _elements(data, 128, endian):
        if mdtype == MI_COMPRESSED:
            inner = _inflate(body, max_bytes)
            elements = list(_elements(inner, 0, endian))
        else:
            elements = [(mdtype, body)]
        for inner_type, inner_body in elements:
            if inner_type == MI_MATRIX:
                name, array = _matrix(inner_body, endian)
                if array is not None:
                    variables[name] = array
    return variables


def _elements(buffer: bytes, start: int, endian: str):
    """Yield (type, body) of the data elements in ``buffer[start:]``."""
    position, end = start, len(buffer)
    while position < end:
        if position + 8 > end:
            raise MatFormatError(f"truncated element tag at byte {position}")
        first, count = np.frombuffer(buffer, endian + "u4", 2, position)
        if first >> 16:  # small element: count in the upper half, data in the tag's second word
            mdtype, count = int(first & 0xFFFF), int(first >> 16)
            if count > 4:
                raise MatFormatError(f"small element of {count} bytes at byte {position}")
            yield mdtype, buffer[position + 4:position + 4 + count]
            position += 8
            continue
        mdtype, count = int(first), int(count)
        body_end = position + 8 + count
        if body_end > end:
            raise MatFormatError(f"element at byte {position} claims {count} bytes, {end - position - 8} left")
        yield mdtype, buffer[position + 8:body_end]
        position = body_end if mdtype == MI_COMPRESSED else position + 8 + -(-count // 8) * 8


def _inflate(body: bytes, max_bytes: int) -> bytes:
    inflater = zlib.decompressobj()
    try:
        inner = inflater.decompress(body, max_bytes)
    except zlib.error as exc:
        raise MatFormatError(f"damaged compressed element ({exc})") from None
    if inflater.unconsumed_tail:
        raise MatFormatError(f"compressed element inflates past {max_bytes >> 20} MiB")
    return inner


def _matrix(body: bytes, endian: str):
    """(name, float64 array) of a numeric miMATRIX, or (name, None) for other classes."""
    parts = list(_elements(body, 0, endian))
    if len(parts) < 3:
        raise MatFormatError("matrix element without flags, dimensions and name")
    flags = _typed(parts[0], endian)
    dims = _typed(parts[1], endian)
    name = bytes(parts[2][1]).decode("latin-1")
    if flags.size < 1 or dims.size < 2 or (dims < 0).any():
        raise MatFormatError(f"variable {name!r}: bad array flags or dimensions")
    if int(flags[0]) & 0xFF not in NUMERIC_CLASSES:
        return name, None
    if int(flags[0]) & COMPLEX_FLAG:
        raise MatFormatError(f"variable {name!r} is complex; expected real numbers")
    if len(parts) < 4:
        raise MatFormatError(f"variable {name!r} has no data")
    values = _typed(parts[3], endian)
    shape = tuple(int(d) for d in dims)
    if values.size != math.prod(shape):
        raise MatFormatError(f"variable {name!r}: {values.size} values for dimensions {shape}")
    return name, values.astype(np.float64).reshape(shape, order="F")


def _typed(part, endian: str) -> np.ndarray:
    mdtype, body = part
    if mdtype not in MI_TYPES:
        raise MatFormatError(f"unexpected data type {mdtype}")
    dtype = np.dtype(endian + MI_TYPES[mdtype])
    if len(body) % dtype.itemsize:
        raise MatFormatError(f"{len(body)} bytes is not a whole number of {dtype.name} values")
    return np.frombuffer(body, dtype)
