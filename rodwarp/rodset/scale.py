"""Plausibility of a rod set's lengths in its declared units (a CSV does not record its units,
so a file in millimetres read as metres is a thousand times too large: these checks name the
measured sizes and the ``--units`` that would make them plausible)."""

from __future__ import annotations

import math

import numpy as np

from rodwarp._util import one_line_error as _fail
from rodwarp.rodset._units import UNITS

__all__ = ["PLAUSIBLE_LENGTH_M", "mean_length", "median_diameter", "unit_hint", "check_diameter_agrees"]

#: range of mean rod lengths (m) taken as plausible for a physical rod set: a fibre of 10 um
#: to a pole of 100 m; outside it the file's unit is more likely wrong than the rods
PLAUSIBLE_LENGTH_M = (1e-5, 100.0)
#: relative difference between ``--diameter`` and the file's own diameters that is refused
DIAMETER_REL_TOL = 0.05


def mean_length(rods) -> float:
    """Mean polyline length of the rods, in ``rods.units``."""
    return float(np.mean(rods.rod_lengths())) if rods.n_rods else float("nan")


def median_diameter(rods) -> float:
    """Median rod diameter (twice the median radius), in ``rods.units``."""
    return 2.0 * float(np.median(rods.radii)) if rods.n_rods else float("nan")


def _likely_unit(length: float, declared: str) -> str | None:
    """The metric unit other than ``declared`` in which ``length`` (a number) is closest to a
    plausible rod length (geometric middle of :data:`PLAUSIBLE_LENGTH_M`), if that is plausible."""
    lo, hi = PLAUSIBLE_LENGTH_M
    mid = math.log10(math.sqrt(lo * hi))
    best = None
    for u in ("m", "mm", "um"):
        if u == declared or not length > 0:
            continue
        m = length * UNITS[u]
        if lo <= m <= hi and (best is None or abs(math.log10(m) - mid) < abs(math.log10(best[1]) - mid)):
            best = (u, m)
    return None if best is None else best[0]


def unit_hint(rods, extent: float | None = None) -> str | None:
    """A phrase pointing at ``--units`` when the rods' sizes are implausible in their units.

    Parameters
    ----------
    rods : RodSet
        Rods in a metric unit (``voxel`` rods are never judged: a voxel has no fixed size).
    extent : float, optional
        Largest edge of the analysed domain, in ``rods.units``; judged too (at most ten times
        the largest plausible rod length).

    Returns
    -------
    str or None
        E.g. ``"the rods are 1000 m long and 20 m thick in their declared units 'm' (a CSV
        does not record its units): if the file is in mm pass --units mm"``; None when the
        sizes are plausible.
    """
    if rods.units not in UNITS or UNITS[rods.units] is None or rods.n_rods == 0:
        return None
    k = UNITS[rods.units]
    length, d = mean_length(rods), median_diameter(rods)
    lo, hi = PLAUSIBLE_LENGTH_M
    bad = not (lo <= length * k <= hi)
    if extent is not None and math.isfinite(extent) and extent * k > 10 * hi:
        bad = True
    if not bad:
        return None
    u = rods.units
    box = f" in a domain {extent:.4g} {u} wide" if extent is not None else ""
    likely = _likely_unit(length, u)
    fix = (f"if the file is in {likely} pass --units {likely}" if likely
           else "pass the file's unit with --units (m, mm, um)")
    return (f"the rods are {length:.4g} {u} long and {d:.4g} {u} thick{box} in their declared units '{u}', "
            f"implausible for rods ({lo:g} to {hi:g} m long): {fix}")


def check_diameter_agrees(rods, diameter: float | None, source, option: str = "--diameter") -> None:
    """Refuse a ``diameter`` (in ``rods.units``) that contradicts the radii the file holds.

    A rod set whose radii came from ``diameter`` itself (a CSV without a radius column) agrees
    exactly; otherwise a difference of more than :data:`DIAMETER_REL_TOL` from twice the
    median radius is a one-line error saying both values.
    """
    if diameter is None or rods.n_rods == 0:
        return
    d = median_diameter(rods)
    if abs(float(diameter) - d) > DIAMETER_REL_TOL * d:
        raise _fail(f"{option} {float(diameter):g} {rods.units} contradicts the radii in {source} (median diameter "
                    f"{d:.4g} {rods.units}, {abs(float(diameter) - d) / d:.0%} off); drop {option} "
                    f"(it only stands in for a missing radius column)")
