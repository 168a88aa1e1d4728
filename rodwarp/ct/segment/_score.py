"""Scoring a segmentation against a ground truth (a phantom's): rods, filaments, contacts.

* :func:`match_rods` pairs found and true straight rods one-to-one (Hungarian assignment on
  the mean centreline distance, within a distance and an angle);
* :func:`match_polylines` pairs found and true curved filaments one-to-one as curves: a found
  filament matches a true one when it lies along it (mean distance) *and* covers most of it,
  so a wire found as many short pieces scores as missed, and one piece running along two
  wires scores as one match at most;
* :func:`score_contacts` scores the found contacts of the packing through a rod matching,
  leaving out the true gaps no scan can resolve.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rodwarp.ct._voxels import _point_segment_distance
from rodwarp.rodset import Contacts, RodSet, detect_contacts

__all__ = ["RodMatch", "match_rods", "ContactScore", "score_contacts", "PolylineMatch", "match_polylines",
           "resample_polyline"]


def _scores(matched: int, n_found: int, n_true: int) -> tuple[float, float, float]:
    """Precision, recall and F1 of ``matched`` one-to-one matches."""
    prec = matched / n_found if n_found else 0.0
    rec = matched / n_true if n_true else 0.0
    return prec, rec, (2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0)


@dataclass
class _Matching:
    """A one-to-one matching of found to true rods or filaments, and its detection scores.

    Attributes
    ----------
    pairs : (M, 2) int
        ``(found index, true index)`` of every match.
    n_found, n_true : int
        Sizes of the two sets.
    precision, recall, f1 : float
        Detection scores.
    """

    pairs: np.ndarray
    n_found: int
    n_true: int
    precision: float
    recall: float
    f1: float

    def mapping(self) -> dict[int, int]:
        """found index -> true index."""
        return {int(a): int(b) for a, b in self.pairs}


@dataclass
class RodMatch(_Matching):
    """One-to-one matching of found rods to true rods (see :func:`match_rods`).

    Attributes (beyond :class:`_Matching`'s)
    ----------------------------------------
    mean_distance : (M,) float
        Mean distance of the found centreline to the true axis, per match (voxels or the sets'
        unit).
    angle_deg : (M,) float
        Angle between the found and true axes, per match.
    endpoint_error : (M,) float
        Larger of the two endpoint distances (ends paired to minimise it), per match.
    """

    mean_distance: np.ndarray = None
    angle_deg: np.ndarray = None
    endpoint_error: np.ndarray = None


def _ends(rods: RodSet):
    o = rods.offsets
    return rods.points[o[:-1]], rods.points[o[1:] - 1]


def _polyline_samples(poly, s):
    """Points at arc-length fractions s (in [0, 1]) along a polyline."""
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 0:
        return np.repeat(poly[:1], len(s), axis=0)
    q = np.interp(s * cum[-1], cum, np.arange(len(poly), dtype=np.float64))
    k = np.minimum(q.astype(int), len(poly) - 2)
    f = (q - k)[:, None]
    return poly[k] * (1 - f) + poly[k + 1] * f


def _dist_to_polyline(pts, poly):
    """Distance from points (n,3) to a polyline (m,3)."""
    best = np.full(len(pts), np.inf)
    for a, b in zip(poly[:-1], poly[1:]):
        np.minimum(best, _point_segment_distance(pts, a, b), out=best)
    return best


def match_rods(found: RodSet, truth: RodSet, max_mean_distance: float = 2.0,
               max_angle_deg: float = 5.0, n_samples: int = 21) -> RodMatch:
    """Match found rods to true rods one-to-one.

    A found rod may match a true rod when the mean distance of ``n_samples`` points spread
    evenly along the found centreline to the true centreline (polyline) is at most
    ``max_mean_distance`` and the angle between their end-to-end axes is at most
    ``max_angle_deg``.  Among admissible pairs the assignment (Hungarian algorithm) minimises
    the total of the symmetric mean distance (found-to-true and true-to-found averaged), so a
    whole rod is preferred to a fragment of it.  ``mean_distance`` reports found-to-true.

    Parameters
    ----------
    found, truth : RodSet
        Segmented and true rods, in the same units (voxels for phantoms).
    max_mean_distance : float
        Largest admissible mean centreline distance, in those units.
    max_angle_deg : float
        Largest admissible angle between the axes (degrees).
    n_samples : int
        Points along each found centreline.

    Returns
    -------
    RodMatch
        The pairs, their distances, angles and endpoint errors, precision, recall and F1.
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    nf, nt = found.n_rods, truth.n_rods
    fa, fb = _ends(found)
    ta, tb = _ends(truth)
    fu = fb - fa
    tu = tb - ta
    fL = np.linalg.norm(fu, axis=1)
    tL = np.linalg.norm(tu, axis=1)
    fmid, tmid = 0.5 * (fa + fb), 0.5 * (ta + tb)
    s = np.linspace(0.0, 1.0, n_samples)
    cost = np.full((nf, nt), np.inf)
    both = np.full((nf, nt), np.inf)
    ang = np.full((nf, nt), np.inf)
    tpts = [_polyline_samples(truth.rod(j), s) for j in range(nt)]
    tree = cKDTree(tmid)
    reach = 0.5 * (fL.max() + tL.max()) + max_mean_distance + 1e-9 if nf and nt else 0.0
    for i in range(nf):
        poly_f = found.rod(i)
        pts = _polyline_samples(poly_f, s)
        for j in sorted(tree.query_ball_point(fmid[i], reach)):
            c = abs(fu[i] @ tu[j]) / max(fL[i] * tL[j], 1e-300)
            a = math.degrees(math.acos(min(1.0, c)))
            if a > max_angle_deg:
                continue
            d = float(_dist_to_polyline(pts, truth.rod(j)).mean())
            if d <= max_mean_distance:
                cost[i, j] = d
                ang[i, j] = a
                # the assignment also weighs how much of the true rod is covered, so that a
                # whole rod beats a short fragment of it
                both[i, j] = 0.5 * (d + float(_dist_to_polyline(tpts[j], poly_f).mean()))
    big = 1e9
    cm = np.where(np.isfinite(both), both, big)
    if nf and nt:
        ri, ci = linear_sum_assignment(cm)
        ok = np.isfinite(cost[ri, ci])
        ri, ci = ri[ok], ci[ok]
    else:
        ri = ci = np.zeros(0, int)
    pairs = np.stack([ri, ci], 1).astype(np.int64) if len(ri) else np.zeros((0, 2), np.int64)
    e1 = np.maximum(np.linalg.norm(fa[ri] - ta[ci], axis=1), np.linalg.norm(fb[ri] - tb[ci], axis=1))
    e2 = np.maximum(np.linalg.norm(fa[ri] - tb[ci], axis=1), np.linalg.norm(fb[ri] - ta[ci], axis=1))
    prec, rec, f1 = _scores(len(pairs), nf, nt)
    return RodMatch(pairs=pairs, mean_distance=cost[ri, ci], angle_deg=ang[ri, ci],
                    endpoint_error=np.minimum(e1, e2), n_found=nf, n_true=nt,
                    precision=prec, recall=rec, f1=f1)


@dataclass
class ContactScore:
    """Contact detection scores (see :func:`score_contacts`)."""

    tp: int
    fp: int
    fn: int
    ignored: int
    precision: float
    recall: float
    f1: float


def score_contacts(found_contacts: Contacts, truth: RodSet, match: RodMatch,
                   truth_contacts: Contacts | None = None, touch_tol: float = 1e-3,
                   ambiguous: tuple = (0.0, 1.0)) -> ContactScore:
    """Score found contacts against the true contacts through a rod matching.

    True contacts are the true rod pairs with surface gap <= ``touch_tol`` (from
    ``truth_contacts``, else ``truth.contacts``, else computed from the true geometry).  Pairs
    whose true gap lies in the open interval ``ambiguous`` (default (0, 1) voxel: unresolvable)
    are scored apart: a found contact there is neither a hit nor a false alarm.  A found contact
    on a rod that matched no true rod is a false positive; a true contact on an unmatched true
    rod is a miss.

    Parameters
    ----------
    found_contacts : Contacts
        The contacts of the segmented packing (rod ids of the found set).
    truth : RodSet
        The true rods (same units as the gaps below).
    match : RodMatch
        Found-to-true rod matching (:func:`match_rods` or :func:`match_polylines`).
    truth_contacts : Contacts, optional
        True contacts; default ``truth.contacts``, else computed from the true geometry.
    touch_tol : float
        Largest true surface gap (units) that is a contact.
    ambiguous : (float, float)
        Open interval of true gaps (units) scored apart.

    Returns
    -------
    ContactScore
        True and false positives, misses, ignored, precision, recall and F1.
    """
    tc = truth_contacts if truth_contacts is not None else truth.contacts
    geo = detect_contacts(truth, tolerance=max(ambiguous[1], touch_tol) + 1e-9)
    if tc is None:
        tc = geo
    true_pairs = {(int(a), int(b)) for a, b, g in zip(tc.rod_i, tc.rod_j, tc.gap) if g <= touch_tol}
    amb = {(int(a), int(b)) for a, b, g in zip(geo.rod_i, geo.rod_j, geo.gap)
           if ambiguous[0] < g < ambiguous[1] and g > touch_tol}
    amb -= true_pairs
    mp = match.mapping()
    tp = fp = ign = 0
    hit = set()
    for a, b in zip(found_contacts.rod_i, found_contacts.rod_j):
        a, b = int(a), int(b)
        if a not in mp or b not in mp:
            fp += 1
            continue
        p = (min(mp[a], mp[b]), max(mp[a], mp[b]))
        if p in true_pairs:
            if p not in hit:
                tp += 1
                hit.add(p)
        elif p in amb:
            ign += 1
        else:
            fp += 1
    fn = len(true_pairs) - len(hit)
    prec = tp / (tp + fp) if tp + fp else (1.0 if not true_pairs else 0.0)
    rec = tp / (tp + fn) if tp + fn else 1.0
    f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
    return ContactScore(tp=tp, fp=fp, fn=fn, ignored=ign, precision=prec, recall=rec, f1=f1)




def resample_polyline(poly: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` (or less) of arc length along a polyline, both ends included."""
    poly = np.asarray(poly, dtype=np.float64)
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, int(np.ceil(cum[-1] / max(step, 1e-9))) + 1)
    s = np.linspace(0.0, cum[-1], n)
    return np.stack([np.interp(s, cum, poly[:, k]) for k in range(3)], axis=1)


@dataclass
class PolylineMatch(_Matching):
    """One-to-one matching of found filaments to true filaments (see :func:`match_polylines`).

    Attributes (beyond :class:`_Matching`'s)
    ----------------------------------------
    mean_distance : (M,) float
        Mean distance from the found centreline to the true one (the sets' unit).
    coverage : (M,) float
        Fraction of the true centreline within ``cover_distance`` of the found one.
    """

    mean_distance: np.ndarray = None
    coverage: np.ndarray = None


def match_polylines(found: RodSet, truth: RodSet, max_mean_distance: float = 2.0, min_coverage: float = 0.8,
                    cover_distance: float | None = None, step: float = 1.0) -> PolylineMatch:
    """Match found filaments to true filaments one-to-one, as curves.

    A pair is admissible when the mean distance from points every ``step`` along the found
    centreline to the true centreline is at most ``max_mean_distance``, and at least
    ``min_coverage`` of both centrelines lies within ``cover_distance`` (default: the true
    radius plus one, at least ``max_mean_distance``) of the other: a fragment does not match,
    and neither does a piece that strays onto another filament for much of its length.  Among
    admissible pairs the assignment (Hungarian algorithm) minimises the total symmetric mean
    distance.

    Parameters
    ----------
    found, truth : RodSet
        Segmented and true filaments (polylines), in the same units (voxels for phantoms).
    max_mean_distance : float
        Largest admissible mean centreline distance, in those units.
    min_coverage : float
        Share of both centrelines that must lie within ``cover_distance`` of the other.
    cover_distance : float, optional
        Distance (units) within which a centreline point counts as covered.
    step : float
        Spacing (units) of the points sampled along the centrelines.

    Returns
    -------
    PolylineMatch
        The pairs, their mean distances and coverages, precision, recall and F1.
    """
    from scipy.optimize import linear_sum_assignment
    from scipy.spatial import cKDTree

    nf, nt = found.n_rods, truth.n_rods
    fpts = [resample_polyline(found.rod(i), step) for i in range(nf)]
    tpts = [resample_polyline(truth.rod(j), step) for j in range(nt)]
    ttrees = [cKDTree(resample_polyline(truth.rod(j), 0.25 * step)) for j in range(nt)]
    ftrees = [cKDTree(resample_polyline(found.rod(i), 0.25 * step)) for i in range(nf)]
    cost = np.full((nf, nt), np.inf)
    dist = np.full((nf, nt), np.inf)
    cov = np.zeros((nf, nt))
    if nf and nt:
        # candidate pairs: filaments whose sample clouds come near each other
        allt = np.concatenate(tpts)
        owner = np.concatenate([np.full(len(p), j) for j, p in enumerate(tpts)])
        tree = cKDTree(allt)
        for i in range(nf):
            near = tree.query_ball_point(fpts[i], max_mean_distance + 1.0 + float(np.max(truth.radii)))
            cand = np.unique(owner[np.concatenate([np.asarray(q, int) for q in near])]) if len(near) else []
            for j in cand:
                cd = cover_distance if cover_distance is not None else max(max_mean_distance,
                                                                           float(truth.radii[j]) + 1.0)
                d_ft, _ = ttrees[j].query(fpts[i])
                md = float(d_ft.mean())
                if md > max_mean_distance:
                    continue
                d_tf, _ = ftrees[i].query(tpts[j])
                c_t = float(np.mean(d_tf <= cd))
                c_f = float(np.mean(d_ft <= cd))
                if c_t < min_coverage or c_f < min_coverage:
                    continue
                dist[i, j] = md
                cov[i, j] = c_t
                cost[i, j] = 0.5 * (md + float(d_tf.mean()))
    if nf and nt:
        ri, ci = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e9))
        ok = np.isfinite(cost[ri, ci])
        ri, ci = ri[ok], ci[ok]
    else:
        ri = ci = np.zeros(0, int)
    pairs = np.stack([ri, ci], 1).astype(np.int64) if len(ri) else np.zeros((0, 2), np.int64)
    m = len(pairs)
    prec, rec, f1 = _scores(m, nf, nt)
    return PolylineMatch(pairs=pairs, mean_distance=dist[ri, ci], coverage=cov[ri, ci], n_found=nf, n_true=nt,
                         precision=prec, recall=rec, f1=f1)
