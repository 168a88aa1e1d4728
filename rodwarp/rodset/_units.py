"""Length units of rod sets: m, mm, um and CT voxels, converted by exact powers of ten."""

from __future__ import annotations

import math

import numpy as np

from rodwarp._util import one_line_error as _fail

__all__ = ["UNITS"]

#: Metres per unit. ``voxel`` has no fixed metric scale (pass ``voxel_size`` to convert).
UNITS: dict[str, float | None] = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "voxel": None}
#: Decimal exponent of each metric unit, used for exact powers-of-ten conversion.
_EXPONENT = {"m": 0, "mm": -3, "um": -6}


#: largest magnitude of a coordinate, radius, gap or box corner, in the set's own unit (and of a
#: velocity, in that unit per second).  1e12 of any unit (1000 km in um, 7 AU in m) is beyond
#: any packing or scan, while squares and cubes of such values (distances, box volumes) stay far
#: from float64 overflow (1e308): a larger value is a stray or corrupt number, not a length.
#: Sets far smaller than this but spread over many rod lengths are refused with their own
#: message (:func:`rodwarp.rodset.sanity.far_rod`, the engine's and the grid's limits).
MAX_COORDINATE = 1e12

def _positive(v, name: str, what: str = "a positive number") -> float:
    """``v`` as a finite float > 0, else a one-line error naming ``name``."""
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise _fail(f"{name} must be {what}, got {v!r}") from None
    if not (math.isfinite(f) and f > 0):
        raise _fail(f"{name} must be {what}, got {v!r}")
    return f


def check_units(units) -> str:
    if not isinstance(units, str) or units not in UNITS:
        raise _fail(f"unknown units {units!r}; use one of {', '.join(repr(u) for u in UNITS)}")
    return units


def _unit_scale(src: str, dst: str, voxel_size: float | None) -> tuple[float, bool]:
    """Return ``(k, divide)``: converting ``src`` values to ``dst`` is ``x / k`` if divide else ``x * k``.

    Metric conversions use exact powers of ten, multiplying for factors >= 1 and dividing
    otherwise, so each value is correctly rounded (``m -> mm`` is exactly ``x * 1000``).
    """
    check_units(src)
    check_units(dst)
    if voxel_size is not None:
        if "voxel" not in (src, dst) or src == dst:
            raise _fail(f"voxel_size only applies to conversions to or from 'voxel' (got {src!r} -> {dst!r})")
        voxel_size = _positive(voxel_size, "voxel_size", "a positive number in metres")
    if src == dst:
        return 1.0, False
    if "voxel" in (src, dst):
        if voxel_size is None:
            raise _fail(f"cannot convert {src!r} to {dst!r} without a scale; pass voxel_size= (metres per voxel)")
        # metric units are m, mm, um (exponent <= 0), so one voxel is voxel_size * 10**-e of them
        if src == "voxel":
            return voxel_size * 10.0 ** (-_EXPONENT[dst]), False
        return voxel_size * 10.0 ** (-_EXPONENT[src]), True
    k = _EXPONENT[src] - _EXPONENT[dst]
    return (10.0 ** k, False) if k >= 0 else (10.0 ** (-k), True)


def _scale(a: np.ndarray | None, k: float, divide: bool) -> np.ndarray | None:
    if a is None:
        return None
    return a / k if divide else a * k
