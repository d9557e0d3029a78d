"""The ``clsdcam`` command line: one module per command (``add_parser`` and ``run``), shared options and
argument types in :mod:`clsdcam.cli.options`, every heavy import inside a command's ``run``.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback, no output file; a file or folder that
cannot be read or written is bad input too), 130 interrupted (no partial output file).
"""
from __future__ import annotations

import errno
import os
import sys

from ..data import data_folder
from ..errors import InputError

# file-system errors that say something about a path the user gave (exit 2), not about clsdcam
PATH_ERRORS = frozenset({errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOTDIR, errno.EISDIR, errno.EEXIST,
                         errno.ENOENT, errno.ENOSPC, errno.EDQUOT, errno.ENAMETOOLONG})


class PipeGuard:
    """stdout that keeps going when the reader of a pipe has left (``clsdcam … | head``): the rest of the
    output goes to the null device instead of a BrokenPipeError traceback, and the command finishes its work."""

    def __init__(self, stream):
        self.stream = stream

    def write(self, text: str) -> int:
        try:
            return self.stream.write(text)
        except BrokenPipeError:
            self._to_null()
            return len(text)

    def flush(self):
        try:
            self.stream.flush()
        except BrokenPipeError:
            self._to_null()

    def _to_null(self):
        """Point the stream (and its file descriptor, which Python flushes at exit) at the null device."""
        null = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(null, self.stream.fileno())
        except (OSError, ValueError, AttributeError):      # no file descriptor (e.g. captured): a new stream
            self.stream = os.fdopen(null, "w", encoding="utf-8")
        else:
            os.close(null)

    def __getattr__(self, name):
        return getattr(self.stream, name)


def main(argv=None) -> int:
    stdout, sys.stdout = sys.stdout, PipeGuard(sys.stdout)
    try:
        return _main(argv)
    finally:
        sys.stdout = stdout


def _main(argv) -> int:
    from .options import build_parser, command_module, commands

    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            raise InputError("a command is needed: " + ", ".join(commands()) + " (clsdcam --help says what each does)")
        with data_folder(getattr(args, "data", None)):
            return command_module(args.command).run(args)
    except InputError as exc:
        print(f"clsdcam: error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        if exc.errno not in PATH_ERRORS:
            raise
        print(f"clsdcam: error: {path_error_text(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("clsdcam: interrupted; no output written", file=sys.stderr)
        return 130


def path_error_text(exc: OSError) -> str:
    """One line for a file-system error: the path and what went wrong."""
    path = f"{exc.filename}: " if exc.filename else ""
    return f"{path}{exc.strerror or exc}"
