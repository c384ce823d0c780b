"""The one error type of the reference: printed as one line, exit status 1."""


class RunError(Exception):
    """Bad input or a failed run; the message names the culprit."""
