"""Errors a user can act on: one line naming the file or value and what is wrong."""

import numbers


class InputError(ValueError):
    """Bad user input (mesh file, config value). The message is one line and self-contained."""


def checked_int(value: object, name: str, least: int) -> int:
    """value as an int >= least: an integer, or a whole float such as Hydra's 1e5 (a bool or a string is not
    one); an InputError naming name=value otherwise."""
    whole = isinstance(value, numbers.Real) and not isinstance(value, bool) and float(value).is_integer()
    if not whole or value < least:  # type: ignore[operator]
        raise InputError(f"{name}={value!r}: must be an integer >= {least}")
    return int(value)  # type: ignore[call-overload]


def first_line(err: BaseException) -> str:
    """The first line of err's message ('' for none)."""
    return (str(err).strip().splitlines() or [""])[0]


def one_line(err: BaseException) -> str:
    """'ExceptionType: first line of its message', for a report or a note."""
    return f"{type(err).__name__}: {first_line(err)}"
