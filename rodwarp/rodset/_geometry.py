"""Geometry of a rod set on the host (vectorised NumPy): segment distances and its contacts.

Three words are kept apart here and wherever these functions are used:

* the **contacts of the packing** - touching rod pairs, one :class:`~rodwarp.rodset.Contacts`
  entry per pair (what :func:`detect_contacts` returns);
* **contact candidates** - segment pairs close enough to be tested (here from a k-d tree on
  segment midpoints), most of which do not touch;
* the **contact point** of a contact - the midpoint of the two closest points of its rods.

Used by analysis (contacts when the input has none), CT segmentation and phantoms, random
packing and the tests; this module must not import warp.
"""

from __future__ import annotations

import numpy as np

from rodwarp.arguments import instance, real
from rodwarp.rodset._rodset import MAX_COORDINATE, Contacts, RodSet

__all__ = ["segment_closest_params", "segment_distance", "detect_contacts"]


def segment_closest_params(p0, p1, q0, q1):
    """Closest-point parameters (s, t) in [0, 1] of segments p0-p1 and q0-q1 (broadcasting).

    Parallel pairs take the middle of their overlap, as the Warp narrowphase does.

    Parameters
    ----------
    p0, p1, q0, q1 : array_like, shape (..., 3)
        Segment ends, any length unit; leading axes broadcast.

    Returns
    -------
    s, t : ndarray, shape (...)
        The closest points are ``p0 + s (p1 - p0)`` and ``q0 + t (q1 - q0)``.
    """
    p0, p1, q0, q1 = (np.asarray(a, dtype=np.float64) for a in (p0, p1, q0, q1))
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = np.einsum("...i,...i", d1, d1)
    e = np.einsum("...i,...i", d2, d2)
    f = np.einsum("...i,...i", d2, r)
    c = np.einsum("...i,...i", d1, r)
    b = np.einsum("...i,...i", d1, d2)
    den = a * e - b * b
    tiny = 1e-300
    par = den <= 1e-12 * a * e
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(par | (a <= tiny), 0.0, np.clip((b * f - c * e) / np.where(den > 0, den, 1.0), 0.0, 1.0))
        # parallel: project q's ends on p, take the middle of the overlap
        sq0 = np.where(a > tiny, -c / np.where(a > tiny, a, 1.0), 0.0)
        sq1 = np.where(a > tiny, (b - c) / np.where(a > tiny, a, 1.0), 0.0)
        lo = np.clip(np.minimum(sq0, sq1), 0.0, 1.0)
        hi = np.clip(np.maximum(sq0, sq1), 0.0, 1.0)
        s = np.where(par & (a > tiny), 0.5 * (lo + hi), s)
        t = np.where(e > tiny, (b * s + f) / np.where(e > tiny, e, 1.0), 0.0)
        t_cl = np.clip(t, 0.0, 1.0)
        s = np.where((t != t_cl) & (a > tiny), np.clip((b * t_cl - c) / np.where(a > tiny, a, 1.0), 0.0, 1.0), s)
    return s, t_cl


def segment_distance(p0, p1, q0, q1):
    """Distance between segments p0-p1 and q0-q1 (broadcasting over leading axes).

    Parameters
    ----------
    p0, p1, q0, q1 : array_like, shape (..., 3)
        Segment ends, any length unit.

    Returns
    -------
    ndarray, shape (...)
        Centreline distance, in the unit of the ends (subtract the radii for a surface gap).
    """
    s, t = segment_closest_params(p0, p1, q0, q1)
    p0, p1, q0, q1 = (np.asarray(a, dtype=np.float64) for a in (p0, p1, q0, q1))
    pa = p0 + s[..., None] * (p1 - p0)
    pb = q0 + t[..., None] * (q1 - q0)
    return np.linalg.norm(pa - pb, axis=-1)


def detect_contacts(rods, tolerance: float | None = None):
    """The contacts of a packing from its geometry: rod pairs whose surfaces come within ``tolerance``.

    Used when a rod set carries no contacts (a CSV of centrelines, for example).  Contact
    candidates (segment pairs of distinct rods) come from a k-d tree on segment midpoints; each
    candidate's gap is its exact capsule gap.

    Parameters
    ----------
    rods : RodSet
        The rods, in any length unit.
    tolerance : float, optional
        Largest surface gap counted as a contact, in the rod set's units (negative: only
        overlaps deeper than that; within 1e12); default d / 10 with d the mean rod diameter.

    Returns
    -------
    Contacts
        One entry per touching rod pair: the closest of its segment pairs, contact point at
        the midpoint of the two closest points, gap = centreline distance - r_i - r_j (the
        rod set's units).
    """
    from scipy.spatial import cKDTree

    instance("rods", rods, RodSet, "a RodSet")
    p0, p1, rod = rods.segments()
    if tolerance is None:
        tolerance = 0.1 * float(np.mean(rods.diameters))
    else:  # negative: only overlaps deeper than |tolerance| count
        tolerance = real("tolerance", tolerance, ge=-MAX_COORDINATE, le=MAX_COORDINATE, unit=rods.units,
                         hint="a surface gap")
    if len(rod) < 2:
        return Contacts.empty()
    mid = 0.5 * (p0 + p1)
    half = 0.5 * float(np.max(np.linalg.norm(p1 - p0, axis=1)))
    reach = 2.0 * half + 2.0 * float(np.max(rods.radii)) + tolerance
    candidates = cKDTree(mid).query_pairs(reach, output_type="ndarray")
    if len(candidates) == 0:
        return Contacts.empty()
    a, b = candidates[:, 0], candidates[:, 1]
    keep = rod[a] != rod[b]
    a, b = a[keep], b[keep]
    s, t = segment_closest_params(p0[a], p1[a], p0[b], p1[b])
    pa = p0[a] + s[:, None] * (p1[a] - p0[a])
    pb = p0[b] + t[:, None] * (p1[b] - p0[b])
    gap = np.linalg.norm(pa - pb, axis=1) - rods.radii[rod[a]] - rods.radii[rod[b]]
    hit = gap < tolerance
    ri, rj = rod[a][hit], rod[b][hit]
    lo, hi = np.minimum(ri, rj), np.maximum(ri, rj)
    g, pts = gap[hit], 0.5 * (pa[hit] + pb[hit])
    if len(lo) == 0:
        return Contacts.empty()
    order = np.lexsort((g, hi, lo))
    lo, hi, g, pts = lo[order], hi[order], g[order], pts[order]
    first = np.ones(len(lo), bool)
    first[1:] = (lo[1:] != lo[:-1]) | (hi[1:] != hi[:-1])
    return Contacts(lo[first], hi[first], pts[first], g[first])
