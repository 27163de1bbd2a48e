"""Errors a user can act on: one line naming the file or value and what is wrong."""


class InputError(ValueError):
    """Bad user input (mesh file, config value). The message is one line and self-contained."""
