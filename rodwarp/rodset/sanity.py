"""Checks that a loaded rod set describes rods that can be simulated or analysed.

:class:`~rodwarp.rodset.RodSet` validation checks the arrays (shapes, finite values, positive
radii); these checks look at the geometry the arrays describe, and refuse three inputs that
commands would otherwise accept without a word:

* a rod of zero length (all its vertices at one point): it has no axis, so neither an
  orientation nor contacts are defined for it;
* duplicated rods (the same polyline twice, either direction): a copy-paste or a double
  export, which analysis would count as a contact per pair and simulation as a full overlap;
* a rod far from all the others (a stray coordinate, a unit mix-up): the container of
  ``simulate`` and the grid of ``analyze`` both span the rods' bounding box.

Every check raises :class:`~rodwarp.errors.RodwarpError` with one line that names the rod(s)
and the fix.  This module must not import warp.
"""

from __future__ import annotations

import numpy as np

from rodwarp._util import one_line_error as _fail

__all__ = ["check_rod_geometry", "zero_length_rods", "duplicate_rods", "far_rod",
           "DUPLICATE_TOLERANCE", "FAR_MIN_LENGTHS", "FAR_SPREAD_FACTOR", "MAX_EXTENT_LENGTHS"]

#: endpoints (and the halfway point along the arc) closer than this many rod lengths count as
#: the same: 1e-6 l is far below any real gap between rods (a CT voxel is ~1e-2 l, a packing's
#: smallest gap ~1e-3 d) yet far above the rounding of a saved and reloaded copy (~1e-16 l)
DUPLICATE_TOLERANCE = 1e-6
#: a rod is "far" when its centre lies more than FAR_MIN_LENGTHS mean rod lengths plus
#: FAR_SPREAD_FACTOR times the 90th percentile of the other rods' distances from the median
#: centre.  The median centre and the percentile are robust: a few stray rods move neither, so
#: the rule finds a stray rod even in a large set, while a set spread evenly over any box (a
#: dilute gas of rods included) has no rod beyond about 1.1 times its 90th percentile and is
#: never flagged.  100 rod lengths is more than any packing or CT sample spans around its bulk.
FAR_MIN_LENGTHS = 100.0
FAR_SPREAD_FACTOR = 10.0
#: bounding-box extent (in mean rod lengths) above which a set is refused whatever its shape:
#: the default analysis grid (spacing sqrt(d l) / 2, about l / 10 at alpha 20) over 1000 rod
#: lengths has ~1e12 voxels, and simulate's container would be 1000 rod lengths wide for rods
#: that fill a tiny part of it.  Catches what the outlier rule cannot: two far-apart clusters.
MAX_EXTENT_LENGTHS = 1000.0


def zero_length_rods(rods) -> np.ndarray:
    """Indices of the rods whose polyline has zero (or non-positive) arc length.

    Parameters
    ----------
    rods : RodSet
        Any units.

    Returns
    -------
    (k,) int64 ndarray
        Rod indices, ascending.
    """
    return np.flatnonzero(~(rods.rod_lengths() > 0)).astype(np.int64)


def _halfway(rods, lengths: np.ndarray) -> np.ndarray:
    """(N, 3) point at half the arc length of each rod (direction independent, unlike the
    vertex mean, which depends on how the rod is sampled)."""
    inc = np.zeros(rods.n_vertices)
    inc[1:][rods._segment_mask()] = rods.segment_lengths()
    arc = np.cumsum(inc)  # non-decreasing; flat across the join between two rods
    start, stop = rods.offsets[:-1], rods.offsets[1:]
    target = arc[start] + 0.5 * lengths
    k = np.clip(np.searchsorted(arc, target, side="right") - 1, start, stop - 2)
    span = arc[k + 1] - arc[k]
    t = np.divide(target - arc[k], span, out=np.zeros_like(span), where=span > 0)
    return rods.points[k] + np.clip(t, 0.0, 1.0)[:, None] * (rods.points[k + 1] - rods.points[k])


def duplicate_rods(rods, tolerance: float = DUPLICATE_TOLERANCE) -> list[tuple[int, int]]:
    """Pairs of rods that are the same polyline within ``tolerance`` rod lengths.

    Two rods match when their endpoints coincide (in the same or the reversed order) and so
    do their halfway points along the arc, all within ``tolerance`` times the mean rod length
    (the comparison is of the geometry, not of the vertex count).

    Parameters
    ----------
    rods : RodSet
        Any units; zero-length rods should be refused first (:func:`zero_length_rods`).
    tolerance : float
        In mean rod lengths (dimensionless).

    Returns
    -------
    list of (i, j)
        ``i < j``, sorted.
    """
    from scipy.spatial import cKDTree

    n = rods.n_rods
    if n < 2:
        return []
    lengths = rods.rod_lengths()
    tol = tolerance * float(np.mean(lengths))
    if not tol > 0:
        return []
    first = rods.points[rods.offsets[:-1]]
    last = rods.points[rods.offsets[1:] - 1]
    mid = _halfway(rods, lengths)
    # one 9-vector per rod and per direction; the reversed key of rod j equals the forward key
    # of rod i when j is i reversed
    fwd = np.hstack([first, last, mid])
    rev = np.hstack([last, first, mid])
    tree = cKDTree(fwd)
    pairs = set()
    # the Chebyshev norm: each coordinate within tol
    for keys in (fwd, rev):
        for i, hits in enumerate(tree.query_ball_point(keys, r=tol, p=np.inf)):
            for j in hits:
                if j != i:
                    pairs.add((min(i, j), max(i, j)))
    return sorted(pairs)


def far_rod(rods) -> tuple[int, float, float, str] | None:
    """The rod that lies far from the others, if any (the rule is in the module's constants).

    Parameters
    ----------
    rods : RodSet
        Any units: the distances returned are in ``rods.units``.

    Returns
    -------
    (rod, distance, bulk, rule) or None
        The rod index, its centre's distance from the median centre of all rods and the
        90th percentile of those distances (both in ``rods.units``), and which rule found it
        (``"outlier"`` or ``"extent"``); None when the set is compact enough.
    """
    n = rods.n_rods
    if n < 2:
        return None
    ell = float(np.mean(rods.rod_lengths()))
    if not ell > 0:
        return None
    centres = np.add.reduceat(rods.points, rods.offsets[:-1], axis=0) / rods.vertex_counts[:, None]
    dist = np.linalg.norm(centres - np.median(centres, axis=0), axis=1)
    k = int(np.argmax(dist))
    bulk = float(np.percentile(dist, 90))
    if dist[k] > FAR_MIN_LENGTHS * ell + FAR_SPREAD_FACTOR * bulk:
        return k, float(dist[k]), bulk, "outlier"
    extent = float(np.max(np.ptp(rods.bounding_box(), axis=0)))
    if extent > MAX_EXTENT_LENGTHS * ell:
        return k, float(dist[k]), bulk, "extent"
    return None


def check_rod_geometry(rods, where: str) -> None:
    """Refuse zero-length rods, duplicated rods and a rod far from the others.

    Parameters
    ----------
    rods : RodSet
        The loaded set (any units).
    where : str
        How the message names the input, e.g. ``"--initial packing.npz"`` or ``"packing.npz"``.

    Raises
    ------
    RodwarpError
        One line naming the rod(s), what is wrong and the fix.
    """
    zero = zero_length_rods(rods)
    if zero.size:
        more = f" ({zero.size} rods have zero length)" if zero.size > 1 else ""
        raise _fail(f"{where}: rod {int(zero[0])} has zero length{more}; remove it")
    dup = duplicate_rods(rods)
    if dup:
        i, j = dup[0]
        shown = ", ".join(f"{a} and {b}" for a, b in dup[:5]) + (f" and {len(dup) - 5} more pairs"
                                                                  if len(dup) > 5 else "")
        raise _fail(f"{where}: rods {shown} are duplicates (the same polyline within "
                    f"{DUPLICATE_TOLERANCE:g} rod lengths); remove the duplicated rods (e.g. rod {j})")
    far = far_rod(rods)
    if far is not None:
        k, d, bulk, rule = far
        u = rods.units
        ell = float(np.mean(rods.rod_lengths()))
        why = (f"while 90% of the rods lie within {bulk:.3g} {u} of it" if rule == "outlier" else
               f"and the rods span more than {MAX_EXTENT_LENGTHS:g} rod lengths")
        raise _fail(f"{where}: rod {k} lies {d:.3g} {u} ({d / ell:.3g} rod lengths) from the rods' median centre, "
                    f"{why}; the container or grid would span that distance: remove rod {k} or fix its "
                    f"coordinates (a stray value or a unit mix-up?)")
