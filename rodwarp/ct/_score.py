"""Scoring segmented filaments (polylines) against a ground truth.

:func:`match_polylines` pairs found and true filaments one-to-one as curves: a found filament
matches a true one when it lies along it (mean distance) *and* covers most of it, so a wire
found as many short pieces scores as missed, and one piece running along two wires scores as
one match at most.  Straight rods are scored with :func:`rodwarp.segment.match_rods`.

This module does not import warp.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rodwarp.rodset import RodSet

__all__ = ["PolylineMatch", "match_polylines", "resample_polyline"]


def resample_polyline(poly: np.ndarray, step: float) -> np.ndarray:
    """Points every ``step`` (or less) of arc length along a polyline, both ends included."""
    poly = np.asarray(poly, dtype=np.float64)
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    n = max(2, int(np.ceil(cum[-1] / max(step, 1e-9))) + 1)
    s = np.linspace(0.0, cum[-1], n)
    return np.stack([np.interp(s, cum, poly[:, k]) for k in range(3)], axis=1)


@dataclass
class PolylineMatch:
    """One-to-one matching of found filaments to true filaments (see :func:`match_polylines`).

    Attributes
    ----------
    pairs : (M, 2) int
        ``(found index, true index)`` of every match.
    mean_distance : (M,) float
        Mean distance from the found centreline to the true one (the sets' unit).
    coverage : (M,) float
        Fraction of the true centreline within ``cover_distance`` of the found one.
    precision, recall, f1 : float
        Filament detection scores.
    """

    pairs: np.ndarray
    mean_distance: np.ndarray
    coverage: np.ndarray
    n_found: int
    n_true: int
    precision: float
    recall: float
    f1: float

    def mapping(self) -> dict[int, int]:
        """found index -> true index."""
        return {int(a): int(b) for a, b in self.pairs}


def match_polylines(found: RodSet, truth: RodSet, max_mean_distance: float = 2.0, min_coverage: float = 0.8,
                    cover_distance: float | None = None, step: float = 1.0) -> PolylineMatch:
    """Match found filaments to true filaments one-to-one, as curves.

    A pair is admissible when the mean distance from points every ``step`` along the found
    centreline to the true centreline is at most ``max_mean_distance``, and at least
    ``min_coverage`` of both centrelines lies within ``cover_distance`` (default: the true
    radius plus one, at least ``max_mean_distance``) of the other: a fragment does not match,
    and neither does a piece that strays onto another filament for much of its length.  Among
    admissible pairs the assignment (Hungarian algorithm) minimises the total symmetric mean
    distance.  Both sets must be in the same units.
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
    prec = m / nf if nf else 0.0
    rec = m / nt if nt else 0.0
    f1 = 2 * prec * rec / (prec + rec) if prec + rec > 0 else 0.0
    return PolylineMatch(pairs=pairs, mean_distance=dist[ri, ci], coverage=cov[ri, ci], n_found=nf, n_true=nt,
                         precision=prec, recall=rec, f1=f1)
