"""Pieces of curved filaments paired into whole filaments, and duplicates dropped.

The skeleton of a tangle falls apart at every crossing and touching run into branches; each
branch lies on one filament (on the wire tangles, every branch does), so tracing the
filaments is pairing the branch ends through the junction gaps.  This stage works on the
*refined* branches (:mod:`rodwarp.ct.segment._curved`):

1. **ends** -- each branch's end is taken ``trim`` inside its last vertex, with point and
   outward tangent from a quadratic fitted to the ``reach`` behind it (a chord lags the bend);
2. **bridges** -- for two ends within ``max_gap`` the bridge is the cubic Hermite curve that
   leaves one end along its tangent and enters the other along its: the curve a smooth
   filament would take through the gap.  It is admissible when the smoothed image stays at or
   above :data:`MIN_LEVEL` of the plateau all along it (through a junction, a crossing, a
   touching run; never across the background between two filaments).  Its cost is its
   turning (the angle between the tangents plus each tangent's angle to the chord) plus
   :data:`IMAGE_WEIGHT` times how far the image along it falls below the plateau;
3. **matching** -- the set of bridges of greatest total worth ``MAX_COST - cost``, each end
   used once, is found exactly (Edmonds' blossom algorithm); a bridge that would close a loop
   is dropped.  Where filaments cross, the straight-through pairings win together;
4. **duplicates** -- a piece that lies for most of its length within one radius of a longer
   filament is the skeleton of a touching run or of a junction, drawn once for two filaments:
   it is dropped.

Coordinates are ``(x, y, z)`` in working voxels.
"""

from __future__ import annotations

import math

import numpy as np

from rodwarp.ct._voxels import _resample

__all__ = ["pair_ends", "drop_duplicates", "hermite"]

# Knobs chosen on 16 development seeds of the wire tangle (0-15, not the benchmark's; filament F1)
# and on the real fibre scan of examples/data (a higher MIN_LEVEL leaves many more doubtful
# filaments there: fused fibres dim the gaps).
#: the smoothed image along a bridge never falls below this share of the filaments' plateau (the
#: half level: a bridge stays inside the binarised foreground)
MIN_LEVEL = 0.5
#: dearest admissible bridge (radians of turning, plus the image term)
MAX_COST = 8.0
#: weight of the image term, ``1 - darkest intensity along the bridge``, in a bridge's cost
IMAGE_WEIGHT = 5.0


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
    """For each piece and side: (end point, outward unit tangent, arc position of the end).

    The end point lies ``trim`` inside the piece (its last radius is pulled by the junction it
    was cut from); the point and its tangent come from a quadratic in arc length fitted to the
    ``reach`` behind it.  A chord over the same stretch lags the bend by half its turning: on the
    wire tangles the chord's tangents were off the true ones by 16 degrees (median), the
    quadratic's by 8.
    """
    out = []
    for p in polys:
        cum = _arc(p)
        L = float(cum[-1])
        t_in = min(trim, 0.2 * L)
        rch = min(reach, max(L - t_in, 2.0))
        for side in (0, 1):
            s = cum if side == 0 else L - cum  # distance from this end
            sel = (s >= t_in) & (s <= t_in + rch)
            if sel.sum() < 4:
                sel = s <= t_in + max(rch, 3.0)
            x, y = s[sel] - t_in, p[sel]
            deg = 2 if len(x) >= 4 else 1
            if len(x) < 2:
                e, t = p[0] if side == 0 else p[-1], np.zeros(3)
            else:
                coef = np.polyfit(x, y, deg)  # rows: highest power first
                e, d = coef[-1], coef[-2]      # value and slope at the end point (x = 0)
                n = float(np.linalg.norm(d))
                t = -d / n if n > 0 else np.zeros(3)  # x grows inwards: outwards is -d/dx
            out.append((np.asarray(e, float), t, t_in if side == 0 else L - t_in))
    return out


def pair_ends(polys, sampler, r0: float, max_gap: float, level: float = MIN_LEVEL,
              max_cost: float = MAX_COST, image_weight: float = IMAGE_WEIGHT,
              trim: float | None = None, reach: float | None = None):
    """Join filament pieces into filaments by a minimum-cost matching of their ends.

    Parameters
    ----------
    polys : list of (m, 3) ndarray
        Refined centrelines ``(x, y, z)`` (voxels), vertices about one voxel apart.
    sampler : callable
        Smoothed, normalised intensity (background 0, filaments 1) at ``(k, 3)`` points; NaN
        outside the volume.
    r0 : float
        Filament radius (voxels).
    max_gap : float
        Longest bridge (voxels, end to end).
    level : float
        The image must stay at or above this normalised intensity all along a bridge.
    max_cost : float
        Dearest admissible bridge (radians, see ``image_weight``); a join is worth
        ``max_cost - cost``, so leaving an end free costs nothing.
    image_weight : float
        Weight of ``1 - (darkest intensity along the bridge)`` in the cost.
    trim, reach : float, optional
        End points ``trim`` inside each piece (default ``r0``), fitted over ``reach`` behind
        them (default ``3 r0``); voxels.

    Returns
    -------
    list of (m, 3) ndarray
        The filaments: chains of pieces and bridges, resampled every voxel.
    int
        Bridges made.

    Notes
    -----
    A bridge is the cubic Hermite curve that leaves one end along its tangent and enters the
    other along its.  Its cost is the turn between the two tangents plus each tangent's angle
    to the chord (radians), plus ``image_weight`` times how far the image along it falls below
    the filaments' plateau.  The set of bridges is the one of greatest total worth with each
    end used once (Edmonds' blossom algorithm, :func:`networkx.max_weight_matching`): at a
    crossing the two straight-through pairings beat the two turns together, where a greedy
    choice takes the cheapest single bridge first and may leave its partner a worse one.  A
    matched bridge that would close a loop is dropped, dearest first.
    """
    import networkx as nx
    from scipy.spatial import cKDTree

    n = len(polys)
    if n < 2:
        return list(polys), 0
    trim = float(r0) if trim is None else float(trim)
    reach = 3.0 * float(r0) if reach is None else float(reach)
    ends = _ends(polys, trim, reach)
    E = np.array([e[0] for e in ends])
    graph = nx.Graph()
    paths = {}
    for a, b in cKDTree(E).query_pairs(max_gap, output_type="ndarray"):
        a, b = int(a), int(b)
        if a // 2 == b // 2:
            continue
        pa, ta, _ = ends[a]
        pb, tb, _ = ends[b]
        c = pb - pa
        dist = float(np.linalg.norm(c))
        cu = c / dist if dist > 1e-9 else ta
        turn = math.acos(float(np.clip(ta @ -tb, -1.0, 1.0)))
        angle_a = math.acos(float(np.clip(ta @ cu, -1.0, 1.0)))
        angle_b = math.acos(float(np.clip(-tb @ cu, -1.0, 1.0)))
        if turn + angle_a + angle_b >= max_cost:
            continue
        pts, _, _ = hermite(pa, ta, pb, -tb, int(math.ceil(dist)) * 2 + 3)
        v = sampler(pts)
        if not np.all(np.isfinite(v)):
            continue
        darkest = float(v.min())
        if darkest < level:
            continue
        cost = turn + angle_a + angle_b + image_weight * (1.0 - min(darkest, 1.0))
        if cost >= max_cost:
            continue
        graph.add_edge(a, b, weight=max_cost - cost)
        paths[(a, b)] = pts
    matched = nx.max_weight_matching(graph)
    parent = list(range(n))

    def root(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    partner: dict[int, tuple[int, np.ndarray]] = {}
    for a, b in sorted(matched, key=lambda e: (-graph[e[0]][e[1]]["weight"], min(e))):
        a, b = min(a, b), max(a, b)
        ra, rb = root(a // 2), root(b // 2)
        if ra == rb:
            continue  # would close a loop
        parent[ra] = rb
        pts = paths[(a, b)]
        partner[a] = (b, pts)
        partner[b] = (a, pts[::-1])
    return _chains(polys, ends, partner), len(partner) // 2


def _chains(polys, ends, partner):
    """Filaments from pieces and the bridges between their ends (``partner``: end -> (end, path))."""
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
