"""Errors caused by the user's input: the CLI prints them as one line and exits non-zero."""


class InputError(ValueError):
    """Bad input given by the user (a file, an option, a value)."""
