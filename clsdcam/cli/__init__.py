"""The ``clsdcam`` command line: one module per command (``add_parser`` and ``run``), shared options and
argument types in :mod:`clsdcam.cli.options`, every heavy import inside a command's ``run``.

Exit codes: 0 success, 2 bad input (one line on stderr, no traceback, no output file),
130 interrupted (no partial output file).
"""
from __future__ import annotations

import sys

from ..errors import InputError


def main(argv=None) -> int:
    from .options import COMMANDS, build_parser, command_module

    try:
        parser = build_parser()
        args = parser.parse_args(argv)
        if args.command is None:
            raise InputError("a command is needed: " + ", ".join(COMMANDS) + " (clsdcam --help says what each does)")
        return command_module(args.command).run(args)
    except InputError as exc:
        print(f"clsdcam: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("clsdcam: interrupted; no output written", file=sys.stderr)
        return 130
