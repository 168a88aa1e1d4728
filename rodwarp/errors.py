"""Errors that rodwarp reports to users as one line (the CLI prints them without a traceback)."""

from __future__ import annotations


class RodwarpError(ValueError):
    """Bad input or an impossible request: the message says what is wrong and how to fix it."""


class RodwarpTypeError(RodwarpError, TypeError):
    """An argument of the wrong kind (a string where a number goes, a list where a RodSet goes).

    A ``TypeError`` for Python callers, and a :class:`RodwarpError` (so a ``ValueError``) so
    that code catching bad input, the CLI included, reports it as one line like any other.
    """


class StepTooLarge(RodwarpError):
    """A step above the scene's step bound at the speeds it starts from; ``bound`` (s) is the
    largest step the guard accepts. :meth:`rodwarp.sim.RodSolver.adaptive_step` retries it shorter."""

    def __init__(self, message: str, bound: float):
        super().__init__(message)
        self.bound = bound


class SimulationBlowUp(RuntimeError):
    """A run became unphysical (NaN, runaway speed, deep penetration).

    The message names the step, the time and the likely cause. The state the solver was
    given is left untouched, so nothing non-finite reaches results.
    """

    def __init__(self, message: str, step: int = -1, time: float = float("nan"), cause: str = ""):
        super().__init__(message)
        self.step = step
        self.time = time
        self.cause = cause
