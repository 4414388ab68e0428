"""Errors for bad input. Every package raises a subclass of `InputError` for input a user
can fix (a missing file, a corrupt image, a NaN pose, an empty cloud, an unplugged port);
its message names that input. The `ibrnav` command prints these without a traceback."""


class InputError(ValueError):
    """Bad input; the message names the file, port or value and what is wrong with it."""
