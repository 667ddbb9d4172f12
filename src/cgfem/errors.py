"""Errors the command line reports: bad input (exit code 2) and an interrupted run
(exit code 128 + the signal's number)."""

from __future__ import annotations


class InputError(ValueError):
    """Bad user input.

    ``field`` is the dotted path of the offending entry in the case file
    (e.g. ``bodies.link_a.geometry.minor_radius``), or a parameter name when
    raised below the case layer; :meth:`within` prefixes it as the error travels up.
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(field, message)
        self.field = field
        self.message = message

    def within(self, prefix: str) -> "InputError":
        """The same error with ``prefix`` prepended to its field path."""
        field = f"{prefix}.{self.field}" if self.field else prefix
        return InputError(field, self.message)

    def __str__(self) -> str:
        return f"{self.field}: {self.message}" if self.field else self.message


class RunInterrupted(Exception):
    """A run stopped by a signal (SIGINT or SIGTERM) at a progress point: ``signum`` is the
    signal's number; the command line exits with ``128 + signum``."""

    def __init__(self, signum: int) -> None:
        super().__init__(signum)
        self.signum = int(signum)
