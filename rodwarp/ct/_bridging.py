"""Pieces of curved filaments bridged into whole filaments, and duplicates dropped.

The skeleton joins of :mod:`rodwarp.ct._curved` work on the raw skeleton, whose branch ends
bend towards the junction they were cut from; where filaments cross at a shallow angle or
run side by side while touching, the junction region is long and its branch ends point
astray, so a wire comes out in pieces.  This stage works on the *refined* centrelines
instead:

1. **ends** -- each piece's end is taken ``trim`` inside its last vertex (the last radius is
   pulled by the junction) with the outward tangent of the stretch behind it
   (``reach``, several radii: long enough to average the noise, short enough for the bend);
2. **bridges** -- for two ends within ``max_gap`` the bridge is the cubic Hermite curve that
   leaves one end along its tangent and enters the other along its: the curve a smooth
   filament would take through the gap.  It is admissible when its sharpest bend keeps a
   radius of curvature of at least ``min_bend_radius``, it stays within one radius of the
   binarised foreground all along (through a junction region, a crossing, a touching run; not
   across the background between two wires), and no stretch longer than :data:`MAX_OFF` radii
   of it lies more than half a radius off the foreground (two filaments that end near each
   other are not one);
3. **choice** -- admissible bridges are taken cheapest first, each end once and never closing
   a loop; the cost is the bridge's dimensionless bending energy (the integral of the squared
   curvature times the chord), plus its chord in units of ``max_gap``, plus the ends' lateral
   offset from each other's lines in radii (:data:`OFFSET_WEIGHT`), so at a crossing the
   straight-through pairings win over the turns, and a near end over a far one;
4. **duplicates** -- a piece that lies for most of its length within one radius of a longer
   filament is the skeleton of a touching run or of a junction, drawn once for two filaments:
   it is dropped.

Coordinates are ``(x, y, z)`` in working voxels.  This module must not import warp.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["bridge_pieces", "drop_duplicates", "hermite"]

#: weight of the ends' lateral offset (in radii) in a bridge's cost (wire tangles, 8 dev seeds,
#: filament F1 median / worst: 0: 0.79 / 0.68, 1: 0.80 / 0.71)
OFFSET_WEIGHT = 1.0
#: longest stretch of a bridge (radii) more than half a radius off the foreground: without it two
#: arcs ending a few voxels apart were bridged into one (arcs F1 0.92 on three seeds, 1.00 with it)
MAX_OFF = 1.0


def _arc(p: np.ndarray) -> np.ndarray:
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])


def _at(p: np.ndarray, cum: np.ndarray, s: float) -> np.ndarray:
    return np.array([np.interp(s, cum, p[:, j]) for j in range(3)])


def hermite(pa, ta, pb, tb, n: int) -> tuple[np.ndarray, float, float]:
    """The cubic Hermite curve from ``pa`` leaving along unit ``ta`` to ``pb`` arriving along
    unit ``tb`` (both tangents in the direction of travel), tangent lengths the chord.

    Returns ``(points (n, 3), smallest radius of curvature, bending energy * chord)``; the
    energy is dimensionless (0 for a straight bridge, 2 pi^2-ish for a U-turn).
    """
    pa, pb, ta, tb = (np.asarray(v, float) for v in (pa, pb, ta, tb))
    L = float(np.linalg.norm(pb - pa))
    s = np.linspace(0.0, 1.0, max(int(n), 3))[:, None]
    h00, h10, h01, h11 = 2 * s ** 3 - 3 * s ** 2 + 1, s ** 3 - 2 * s ** 2 + s, -2 * s ** 3 + 3 * s ** 2, s ** 3 - s ** 2
    m0, m1 = L * ta, L * tb
    pts = h00 * pa + h10 * m0 + h01 * pb + h11 * m1
    d1 = (6 * s ** 2 - 6 * s) * pa + (3 * s ** 2 - 4 * s + 1) * m0 + (-6 * s ** 2 + 6 * s) * pb + (3 * s ** 2 - 2 * s) * m1
    d2 = (12 * s - 6) * pa + (6 * s - 4) * m0 + (-12 * s + 6) * pb + (6 * s - 2) * m1
    sp = np.linalg.norm(d1, axis=1)
    kappa = np.linalg.norm(np.cross(d1, d2), axis=1) / np.maximum(sp ** 3, 1e-12)
    ds = sp / (len(s) - 1)
    energy = float(np.sum(kappa ** 2 * ds) * L) if L > 0 else 0.0
    rmin = float(1.0 / max(kappa.max(), 1e-12))
    return pts, rmin, energy


def _ends(polys, trim: float, reach: float):
    """For each piece and side: (end point, outward unit tangent, arc position of the end)."""
    out = []
    for p in polys:
        cum = _arc(p)
        L = cum[-1]
        t_in = min(trim, 0.2 * L)
        rch = min(reach, max(0.5 * L - t_in, 1.0))
        for side in (0, 1):
            s_end = t_in if side == 0 else L - t_in
            s_back = s_end + rch if side == 0 else s_end - rch
            e = _at(p, cum, s_end)
            t = e - _at(p, cum, min(max(s_back, 0.0), L))
            n = float(np.linalg.norm(t))
            out.append((e, t / n if n > 0 else np.zeros(3), s_end))
    return out


def bridge_pieces(polys, sampler, r0: float, max_gap: float, min_bend_radius: float,
                  level: float = 0.5, trim: float | None = None, reach: float | None = None,
                  support=None, tube: float = 0.0):
    """Join filament pieces through gaps by smooth bridges the image supports.

    Parameters
    ----------
    polys : list of (m, 3) ndarray
        Refined centrelines ``(x, y, z)`` (voxels), vertices about one voxel apart.
    sampler : callable
        Smoothed, normalised intensity (background 0, rods 1) at ``(k, 3)`` points; NaN outside.
    r0 : float
        Filament radius (voxels).
    max_gap : float
        Longest bridge (voxels, end to end).
    min_bend_radius : float
        Smallest radius of curvature a bridge may have (voxels).
    level : float
        Without ``support``: the image must stay at or above this normalised intensity all
        along a bridge.
    trim, reach : float, optional
        End points are taken ``trim`` inside each piece (default ``r0``), tangents over
        ``reach`` behind them (default ``max(4, 3 r0)``).
    support : callable, optional
        Distance (voxels) to the binarised foreground at ``(k, 3)`` points; with it a bridge
        must stay within ``tube`` of the foreground all along (a bridge guessed through a bend
        runs a little off the filament's axis, never off the filament).
    tube : float
        See ``support`` (voxels).

    Returns
    -------
    list of (m, 3) ndarray
        The filaments: chains of pieces and bridges, resampled every voxel.
    int
        Bridges made.
    """
    from scipy.spatial import cKDTree

    n = len(polys)
    if n < 2:
        return list(polys), 0
    trim = float(r0) if trim is None else float(trim)
    reach = max(4.0, 3.0 * r0) if reach is None else float(reach)
    ends = _ends(polys, trim, reach)
    E = np.array([e[0] for e in ends])
    cand = []
    for a, b in cKDTree(E).query_pairs(max_gap, output_type="ndarray"):
        if a // 2 == b // 2:
            continue
        pa, ta, _ = ends[a]
        pb, tb, _ = ends[b]
        c = pb - pa
        dist = float(np.linalg.norm(c))
        # leave a along ta, arrive at b against its outward tangent
        if dist > 1e-6 and (float(ta @ c) <= 0.0 or float(-tb @ c) <= 0.0):
            continue  # an end pointing away from the other: no smooth bridge
        pts, rmin, energy = hermite(pa, ta, pb, -tb, int(math.ceil(dist)) * 2 + 3)
        if rmin < min_bend_radius:
            continue
        # lateral offset: how far each end lies off the other's line, in radii (a filament's
        # continuation lies on its line; a neighbour touching it lies a diameter aside)
        off = 0.0
        if dist > 1e-6:
            off = 0.5 * (float(np.linalg.norm(c - (c @ ta) * ta)) + float(np.linalg.norm(c - (c @ tb) * tb))) / max(r0, 1.0)
        cand.append((energy + dist / max_gap + OFFSET_WEIGHT * off, int(a), int(b), pts))
    cand.sort(key=lambda c: c[0])
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    partner: dict[int, tuple[int, np.ndarray]] = {}
    for cost, a, b, pts in cand:
        if a in partner or b in partner:
            continue
        ra, rb = root(a // 2), root(b // 2)
        if ra == rb:
            continue  # would close a loop
        if support is not None:
            v = support(pts)
            if not np.all(np.isfinite(v)) or float(v.max()) > tube:
                continue
            # nor cross background: the longest stretch more than half a radius off the
            # foreground is at most MAX_OFF radii (two filaments ending near each other)
            run = best = 0
            for o in v > 0.5 * r0:
                run = run + 1 if o else 0
                best = max(best, run)
            if best * dist / max(len(pts) - 1, 1) > MAX_OFF * r0:
                continue
        else:
            v = sampler(pts)
            v = v[np.isfinite(v)]
            if not v.size or float(v.min()) < level:
                continue
        partner[a] = (b, pts)
        partner[b] = (a, pts[::-1])
        parent[ra] = rb
    return _chains(polys, ends, partner), len(partner) // 2


def _chains(polys, ends, partner):
    """Filaments from pieces and the bridges between their ends (``partner``: end -> (end, path))."""
    from rodwarp.ct._curved import _resample

    n = len(polys)
    if not partner:
        return list(polys)
    seen = np.zeros(n, bool)
    out = []
    starts = [i for i in range(n) if (2 * i) not in partner or (2 * i + 1) not in partner]
    for i0 in starts + list(range(n)):
        if seen[i0]:
            continue
        side_in = 0 if (2 * i0) not in partner else 1
        parts = []
        cur = i0
        while True:
            seen[cur] = True
            p = polys[cur]
            cum = _arc(p)
            out_end = 2 * cur + (1 - side_in)
            s_in = ends[2 * cur + side_in][2] if (2 * cur + side_in) in partner else (0.0 if side_in == 0 else cum[-1])
            s_out = ends[out_end][2] if out_end in partner else (cum[-1] if side_in == 0 else 0.0)
            lo, hi = sorted((s_in, s_out))
            keep = (cum > lo) & (cum < hi)
            seg = np.concatenate([[_at(p, cum, lo)], p[keep], [_at(p, cum, hi)]])
            parts.append(seg if side_in == 0 else seg[::-1])
            if out_end not in partner:
                break
            nxt, bridge = partner[out_end]
            if seen[nxt // 2]:
                break
            parts.append(bridge[1:-1])
            cur, side_in = nxt // 2, nxt % 2
        out.append(_resample(np.concatenate([q for q in parts if len(q)]), 1.0))
    return out


def drop_duplicates(polys, r0: float, near: float = 1.2, share: float = 0.6):
    """Drop pieces lying for at least ``share`` of their length within ``near`` x ``r0`` of a
    longer filament (the one skeleton of two touching filaments).  Returns (kept, dropped)."""
    from scipy.spatial import cKDTree

    if len(polys) < 2:
        return list(polys), 0
    lengths = np.array([_arc(p)[-1] for p in polys])
    order = np.argsort(-lengths, kind="stable")
    kept: list[int] = []
    trees = []
    for k in order:
        p = polys[k]
        if trees:
            close = np.zeros(len(p), bool)
            for t in trees:
                d, _ = t.query(p, distance_upper_bound=near * r0)
                close |= np.isfinite(d)
            if close.mean() >= share:
                continue
        kept.append(int(k))
        trees.append(cKDTree(p))
    kept.sort()
    return [polys[k] for k in kept], len(polys) - len(kept)
