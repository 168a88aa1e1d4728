"""Checks of Python arguments at the public API's boundary (rod sets, the engine, the analysis).

A wrong kind of argument (a string where a number goes, a list where a :class:`RodSet` goes)
raises :class:`~rodwarp.errors.RodwarpTypeError` (a ``TypeError`` and a ``RodwarpError``)
naming the argument and what it expects; a value of the right kind out of its range raises
:mod:`rodwarp.validation`'s one-line :class:`~rodwarp.errors.RodwarpError` (a ``ValueError``)
naming the argument, its range and unit.  The ranges themselves live next
to the code they protect (:data:`rodwarp.rodset.MAX_COORDINATE`, :mod:`rodwarp.sim._limits`).

This module must not import warp.
"""

from __future__ import annotations

import numbers

import numpy as np

from rodwarp.errors import RodwarpTypeError
from rodwarp.validation import integer, number

__all__ = ["instance", "real", "whole", "optional_real", "vector", "direction"]


def instance(name: str, value, cls, expects: str):
    """``value`` when it is a ``cls``, else ``TypeError`` naming ``name`` and ``expects``.

    Parameters
    ----------
    name : str
        The Python argument name (``rods``).
    value : object
        The argument.
    cls : type or tuple of types
        What it must be.
    expects : str
        What to pass instead, e.g. ``"a RodSet (RodSet.from_polylines(...))"``.
    """
    if not isinstance(value, cls):
        raise RodwarpTypeError(f"{name} must be {expects}, got {type(value).__name__} {_short(value)}")
    return value


def _short(value) -> str:
    """``repr(value)`` cut to 60 characters (a message stays one readable line)."""
    text = " ".join(repr(value).split())
    return text if len(text) <= 60 else text[:57] + "..."


def _is_real(value) -> bool:
    # bool is a numbers.Real, but True as a friction coefficient is a mistake, not 1.0
    if isinstance(value, (bool, np.bool_)):
        return False
    if isinstance(value, numbers.Real):
        return True
    return isinstance(value, np.ndarray) and value.ndim == 0 and value.dtype.kind in "iuf"


def real(name: str, value, *, unit: str = "", hint: str = "", **bounds) -> float:
    """A finite number within ``bounds`` (``gt``, ``ge``, ``lt``, ``le``), as a float.

    Raises
    ------
    TypeError
        ``value`` is not a real number (a string, a sequence, a bool).
    RodwarpError
        NaN, an infinity or a value out of bounds (:func:`rodwarp.validation.number`).
    """
    if not _is_real(value):
        raise RodwarpTypeError(f"{name} must be a number{f' in {unit}' if unit else ''}, got {type(value).__name__} "
                        f"{_short(value)}")
    return number(name, value, unit=unit, hint=hint, **bounds)


def optional_real(name: str, value, **kw) -> float | None:
    """None, or :func:`real` of ``value``."""
    return None if value is None else real(name, value, **kw)


def whole(name: str, value, *, ge=None, le=None, hint: str = "") -> int:
    """A whole number within ``ge``..``le``, as an int (a float with an integral value passes).

    Raises
    ------
    TypeError
        ``value`` is not a number.
    RodwarpError
        A fraction, NaN, an infinity or a value out of bounds.
    """
    if not _is_real(value):
        raise RodwarpTypeError(f"{name} must be a whole number, got {type(value).__name__} {_short(value)}")
    if isinstance(value, (np.integer, np.floating, np.ndarray)):
        value = value.item()
    if isinstance(value, float):  # NaN, infinities and 1e300 refused with their bounds, not as digits
        number(name, value, ge=ge, le=le, hint=hint)
    return integer(name, value, ge=ge, le=le, hint=hint)


def _three_numbers(name: str, value, what: str) -> np.ndarray:
    """``value`` as three float64 numbers, else a TypeError naming ``name`` (``what`` says what
    the three numbers are: a unit, or a direction)."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = None
    if a is None or a.shape != (3,) or isinstance(value, (str, bytes)):
        raise RodwarpTypeError(f"{name} must be 3 numbers (x, y, z), {what}, got {type(value).__name__} "
                               f"{_short(value)}")
    return a


def vector(name: str, value, *, unit: str, limit: float) -> np.ndarray:
    """Three finite numbers (x, y, z), each of magnitude at most ``limit``, as a (3,) float64 array.

    Parameters
    ----------
    name : str
        The Python argument name (``gravity``); a component is named ``gravity z``.
    value : array_like
        The vector.
    unit : str
        Its unit (``m/s^2``).
    limit : float
        Largest magnitude of the vector, in ``unit``.

    Raises
    ------
    TypeError
        Not three numbers.
    RodwarpError
        A component NaN or infinite, or the vector longer than ``limit``.
    """
    a = _three_numbers(name, value, f"in {unit}")
    for axis, c in zip("xyz", a):
        number(f"{name} {axis}", float(c), ge=-limit, le=limit, unit=unit)
    norm = float(np.linalg.norm(a))
    if norm > limit:
        number(f"the magnitude of {name}", norm, le=limit, unit=unit)
    return a


def direction(name: str, value) -> np.ndarray:
    """The unit vector along ``value``: three finite numbers, not all zero (any length).

    Raises
    ------
    TypeError
        Not three numbers.
    RodwarpError
        A component NaN or infinite, or the zero vector.
    """
    from rodwarp.validation import fail

    a = _three_numbers(name, value, "a direction of any length")
    big = float(np.max(np.abs(a)))
    if not np.all(np.isfinite(a)) or not big > 0:
        fail(f"{name} must be a direction: 3 finite numbers, not all zero, got {a.tolist()}")
    a = a / big  # scaled first, so that the norm of (1e300, 1e300, 0) does not overflow
    return a / np.linalg.norm(a)
