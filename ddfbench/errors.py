"""Errors a user can act on: one line naming the file or value and what is wrong."""


class InputError(ValueError):
    """Bad user input (mesh file, config value). The message is one line and self-contained."""


def one_line(err: BaseException) -> str:
    """'ExceptionType: first line of its message', for a report or a note."""
    return f"{type(err).__name__}: {(str(err).strip().splitlines() or [''])[0]}"
