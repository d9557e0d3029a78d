"""Errors that the command line turns into one line and exit code 2."""


class InputError(ValueError):
    """Bad user input (file, shape, value or parameter).

    The message names the file or parameter and the problem in one line; the
    CLI prints it without a traceback and exits with code 2.
    """


def shape_text(shape) -> str:
    """A shape as messages write it: (64, 320, 448) -> "64×320×448"."""
    return "×".join(str(n) for n in shape)
