"""Errors a user can act on: one line naming the file or value and what is wrong."""

import numbers


class InputError(ValueError):
    """Bad user input (mesh file, config value). The message is one line and self-contained."""


def checked_int(value: object, name: str, least: int) -> int:
    """value as an int >= least (a bool, a float or a string is not one); an InputError naming name=value otherwise."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
        raise InputError(f"{name}={value!r}: expected an integer >= {least}")
    return int(value)


def one_line(err: BaseException) -> str:
    """'ExceptionType: first line of its message', for a report or a note."""
    return f"{type(err).__name__}: {(str(err).strip().splitlines() or [''])[0]}"
