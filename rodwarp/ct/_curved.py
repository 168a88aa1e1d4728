"""Curved filaments (wires, fibres, arcs) traced as polylines from a greyscale CT volume.

Used by :func:`rodwarp.ct.segment_volume` with ``shape="curved"`` (or ``"auto"`` when
the skeleton's branches bend).  Inputs are the prepared volume and the global levels of the
straight-rod pipeline; coordinates are ``(x, y, z)`` in working voxels.

Pipeline (:func:`trace_filaments`):

1. **skeleton** -- Gaussian denoising, binarisation at the half level, 3-D skeleton; voxels
   near a junction (a skeleton voxel with 3 or more neighbours: where filaments touch or
   cross) are removed, so the skeleton falls apart into *branches*, each a simple path ordered
   by the geodesic distance from one of its ends and averaged per unit of that distance.
2. **joining** -- branch ends are joined through the junction gaps by direction and
   continuity: two ends are joined when they face each other (outward tangents within
   ``join_angle`` of antiparallel, the joining chord within ``join_angle`` of both), lie
   within the gap a junction leaves, and the image is foreground along the chord; candidates
   are taken cheapest first (angle plus distance), each end once, so at a crossing the two
   straight-through pairings win over the turns.  Chains of joined branches are filaments.
3. **centreline** -- each filament is resampled every voxel, smoothed along its length,
   and refined against the greyscale: every vertex moves to the intensity centroid of the
   disc normal to the filament, ignoring voxels nearer to another filament (so touching
   filaments do not pull each other), then smoothed again.
4. **radius** -- per filament, from the intensity mass per unit length (voxels assigned to
   their nearest filament), which blur does not change: ``mass = C pi r^2 (L + 4 r / 3)``.
5. **contacts** -- pairs of *distinct* filaments whose surfaces come within the contact
   tolerance (pieces of one filament are one filament, so never in contact with each other).

This module must not import warp.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage


__all__ = ["trace_filaments", "bend_fraction", "FilamentResult"]

#: largest angle (degrees) between facing end tangents, and between each and the chord, of a
#: join (skeleton ends bend towards the junction they were cut from; on the wire tangles 45
#: degrees joined too little: filament F1 0.72, 60: 0.84, 70: 0.905, 75: 0.905)
JOIN_ANGLE = 70.0
#: reach of a join, in units of the gap a junction's removal leaves (2 (junction_radius r + 1) + 2 r + 2)
JOIN_GAP = 1.5
#: end tangents are measured over this many radii of the branch (at least 4 voxels)
JOIN_TANGENT = 1.5
#: ... behind the point this share of that reach inside the end (the last voxel bends towards the
#: junction; wire tangles, 16 dev seeds, F1 median / worst: 0: 0.80 / 0.60, 0.27: 0.83 / 0.65,
#: 0.67: 0.71 / 0.59 on 8 of them)
JOIN_SKIP = 0.27
#: the junction neighbourhood removed is this share of the straight path's (``junction_radius``):
#: smaller gaps to bridge (wire tangles, 8 dev seeds, filament F1 median / worst: 1.0: 0.79 / 0.53,
#: 0.5: 0.80 / 0.68, with the bridges below)
CURVED_JUNCTION = 0.5
#: longest bridge between pieces: this many radii plus 6 voxels (8 r + 6 against 12 r + 6: same median)
BRIDGE_GAP = 8.0
#: tightest bend of a bridge, in radii (wire tangles: 0.5: 0.80, 1: 0.79, 2: 0.71 median F1; the
#: wires themselves bend down to about 6 radii, but a bridge guessed from two end tangents bends
#: more sharply than the wire it replaces: a third of the true bridges have a radius under 1)
BRIDGE_BEND = 0.5


def _order_branch(pts: np.ndarray, pairs: np.ndarray):
    """Order a connected set of skeleton voxels (n, 3) along its longest geodesic path.

    Returns the path as points averaged per unit of geodesic distance from one end (m, 3).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    n = len(pts)
    if n == 1:
        return pts.astype(np.float64)
    w = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    g = coo_matrix((w, (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    d0 = dijkstra(g, directed=False, indices=0)
    d0[~np.isfinite(d0)] = -1
    a = int(np.argmax(d0))
    d = dijkstra(g, directed=False, indices=a)
    d[~np.isfinite(d)] = 0.0
    k = np.floor(d).astype(np.int64)
    cnt = np.bincount(k)
    ok = cnt > 0
    out = np.stack([np.bincount(k, weights=pts[:, j].astype(np.float64)) for j in range(3)], 1)[ok] / cnt[ok][:, None]
    return out


def _resample(poly: np.ndarray, step: float) -> np.ndarray:
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    if cum[-1] <= 1e-9:
        return poly[:1].repeat(2, 0)
    n = max(2, int(math.ceil(cum[-1] / step)) + 1)
    s = np.linspace(0.0, cum[-1], n)
    return np.stack([np.interp(s, cum, poly[:, j]) for j in range(3)], 1)


def _smooth(poly: np.ndarray, sigma: float) -> np.ndarray:
    """Gaussian smoothing along a unit-spaced polyline; the ends stay anchored (reflected)."""
    if len(poly) < 5 or sigma <= 0:
        return poly
    # odd reflection about the end points keeps the ends in place and straight-ish
    k = min(len(poly) - 1, int(3 * sigma) + 1)
    head = 2 * poly[0] - poly[k:0:-1]
    tail = 2 * poly[-1] - poly[-2:-k - 2:-1]
    ext = np.concatenate([head, poly, tail])
    sm = ndimage.gaussian_filter1d(ext, sigma, axis=0, mode="nearest")
    return sm[k:k + len(poly)]


def _branches(mask: np.ndarray, r0: float, junction_radius: float):
    """Skeleton branches (ordered (m, 3) xyz arrays) with junction neighbourhoods removed;
    also the junction voxels (xyz) and the skeleton size."""
    from rodwarp.ct._seeds import _components, _skeleton

    idx, junc, keep = _skeleton(mask, r0, junction_radius)
    if len(idx) == 0:
        return [], np.zeros((0, 3)), 0
    pts = idx[keep]
    out = []
    if len(pts):
        pairs, _, ncomp, lab, order, bounds = _components(pts)
        n = len(pts)
        pl = lab[pairs[:, 0]] if len(pairs) else np.zeros(0, int)
        porder = np.argsort(pl, kind="stable")
        pb = np.searchsorted(pl[porder], np.arange(ncomp + 1))
        for k in range(ncomp):
            mem = order[bounds[k]:bounds[k + 1]]
            if len(mem) < 3:
                continue
            remap = np.full(n, -1)
            remap[mem] = np.arange(len(mem))
            pp = pairs[porder[pb[k]:pb[k + 1]]]
            path = _order_branch(pts[mem][:, ::-1].astype(np.float64), remap[pp])
            if len(path) >= 2:
                out.append(path)
    return out, junc[:, ::-1].astype(np.float64), len(idx)


def bend_fraction(branches, tol: float, min_length: float) -> float:
    """Share of the skeleton length (branches longer than ``min_length``) in branches that leave
    their chord by more than ``tol``: near 0 for straight rods, large for curved filaments."""
    tot = bent = 0.0
    for b in branches:
        L = float(np.linalg.norm(np.diff(b, axis=0), axis=1).sum())
        if L < min_length:
            continue
        d = b[-1] - b[0]
        n = float(np.linalg.norm(d))
        w = b - b[0]
        if n > 0:
            dev = np.linalg.norm(w - np.outer(w @ d / (n * n), d), axis=1).max()
        else:
            dev = np.linalg.norm(w, axis=1).max()
        tot += L
        if dev > tol:
            bent += L
    return bent / tot if tot > 0 else 0.0


def _end_tangent(b: np.ndarray, side: int, reach: float, skip: float = 0.0) -> np.ndarray:
    """Outward unit tangent at one end of an ordered branch (side 0: first point, 1: last), over
    ``reach`` voxels behind the point ``skip`` voxels inside the end (as far as the branch allows)."""
    q = b if side == 1 else b[::-1]
    seg = np.linalg.norm(np.diff(q[::-1], axis=0), axis=1)
    cum = np.concatenate([[0.0], np.cumsum(seg)])
    skip = min(skip, 0.3 * cum[-1])
    j = min(int(np.searchsorted(cum, skip)), len(q) - 2)
    k = int(np.searchsorted(cum, skip + reach))
    k = min(max(k, j + 1), len(q) - 1)
    t = q[-1 - j] - q[-1 - k]
    n = float(np.linalg.norm(t))
    return t / n if n > 0 else np.zeros(3)


def _chord_filled(sampler, p, q, level=0.5):
    L = float(np.linalg.norm(q - p))
    if L < 1e-9:
        return True
    ss = np.linspace(0.0, 1.0, max(2, int(math.ceil(L / 0.5)) + 1))
    v = sampler(p + ss[:, None] * (q - p))
    v = v[np.isfinite(v)]
    return bool(v.size and np.min(v) >= level)


def _join(branches, r0, P, sampler, max_angle=None, gap_scale=None):
    """Chains of branch ends joined through junction gaps: list of [(branch, reversed), ...]."""
    from scipy.spatial import cKDTree

    max_angle = JOIN_ANGLE if max_angle is None else max_angle
    gap_scale = JOIN_GAP if gap_scale is None else gap_scale
    nbr = len(branches)
    if nbr == 0:
        return []
    reach_t = max(4.0, JOIN_TANGENT * r0)
    ends = []
    for i, b in enumerate(branches):
        for side in (0, 1):
            ends.append((i, side, b[0] if side == 0 else b[-1], _end_tangent(b, side, reach_t, JOIN_SKIP * reach_t)))
    E = np.array([e[2] for e in ends])
    gap = gap_scale * (2.0 * (P.junction_radius * r0 + 1.0) + 2.0 * r0 + 2.0)
    cos_max = math.cos(math.radians(max_angle))
    cand = []
    for a, b in cKDTree(E).query_pairs(gap, output_type="ndarray"):
        ia, sa, pa, ta = ends[a]
        ib, sb, pb, tb = ends[b]
        if ia == ib:
            continue
        if float(ta @ -tb) < cos_max:
            continue
        c = pb - pa
        dist = float(np.linalg.norm(c))
        if dist > 1.5:
            cu = c / dist
            ca, cb = float(ta @ cu), float(-tb @ cu)
            if ca < cos_max or cb < cos_max:
                continue
        else:
            ca = cb = 1.0
        # angle terms in radians, the distance in units of the junction gap
        cost = (math.acos(min(1.0, float(ta @ -tb))) + math.acos(min(1.0, ca)) + math.acos(min(1.0, cb))
                + dist / gap)
        cand.append((cost, a, b))
    cand.sort()
    partner = {}
    for cost, a, b in cand:
        if a in partner or b in partner:
            continue
        if not _chord_filled(sampler, ends[a][2], ends[b][2]):
            continue
        partner[a] = b
        partner[b] = a
    # walk the chains: end index e = 2 * branch + side
    seen = np.zeros(nbr, bool)
    chains = []
    for start in range(nbr):
        if seen[start]:
            continue
        # go to one free end of this chain (or around a loop)
        i, side = start, 0
        steps = 0
        while (2 * i + side) in partner and steps <= nbr:
            e = partner[2 * i + side]
            i, side = e // 2, 1 - (e % 2)
            steps += 1
            if i == start:
                break
        # now walk forward from end (i, side): the branch is traversed from `side` to the other end
        chain = []
        cur, s_in = i, side
        while not seen[cur]:
            seen[cur] = True
            chain.append((cur, s_in == 1))  # entered at its last point: reversed
            out_end = 2 * cur + (1 - s_in)
            if out_end not in partner:
                break
            e = partner[out_end]
            cur, s_in = e // 2, e % 2
        chains.append(chain)
    return chains


def _assemble(branches, chain):
    parts = []
    for i, rev in chain:
        b = branches[i]
        parts.append(b[::-1] if rev else b)
    return np.concatenate(parts)


def _refine_centrelines(polys, sampler, r0, n_iter=3, own_weight=None):
    """Move every vertex to the intensity centroid of its normal disc, ignoring samples nearer
    to another filament; vertices are unit-spaced, so the disc is also a unit-thick slab."""
    from scipy.spatial import cKDTree

    if not polys:
        return polys
    rr = max(r0, 1.0) + 1.0
    g = np.arange(-math.ceil(rr), math.ceil(rr) + 1, 0.5)
    a, b = np.meshgrid(g, g, indexing="ij")
    offs = np.stack([a.ravel(), b.ravel()], 1)
    offs = offs[(offs ** 2).sum(1) <= rr * rr]
    for _ in range(n_iter):
        allp = np.concatenate(polys)
        owner = np.concatenate([np.full(len(p), k) for k, p in enumerate(polys)])
        tree = cKDTree(allp)
        new = []
        for k, p in enumerate(polys):
            if len(p) < 3:
                new.append(p)
                continue
            t = np.gradient(p, axis=0)
            t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
            # a basis of each normal plane
            ref = np.where(np.abs(t[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
            e1 = np.cross(t, ref)
            e1 /= np.linalg.norm(e1, axis=1, keepdims=True)
            e2 = np.cross(t, e1)
            q = p[:, None, :] + offs[None, :, 0, None] * e1[:, None, :] + offs[None, :, 1, None] * e2[:, None, :]
            w = sampler(q.reshape(-1, 3)).reshape(len(p), len(offs))
            w = np.where(np.isfinite(w), np.clip(w, 0.0, 1.0), 0.0)
            # samples nearer to another filament belong to it
            d_nn, j_nn = tree.query(q.reshape(-1, 3), k=1)
            other = (owner[j_nn] != k).reshape(w.shape)
            w = np.where(other, 0.0, w)
            m = w.sum(1)
            ok = m > 0.2 * len(offs)
            ca = (w * offs[:, 0]).sum(1) / np.maximum(m, 1e-12)
            cb = (w * offs[:, 1]).sum(1) / np.maximum(m, 1e-12)
            shift = np.where(ok[:, None], ca[:, None] * e1 + cb[:, None] * e2, 0.0)
            lim = 0.75 * max(r0, 1.0)
            sn = np.linalg.norm(shift, axis=1, keepdims=True)
            shift = np.where(sn > lim, shift * lim / np.maximum(sn, 1e-12), shift)
            new.append(p + shift)
        polys = [_resample(_smooth(p, 1.0), 1.0) if len(p) >= 5 else p for p in new]
    return polys


def _radii(polys, raw_norm: np.ndarray, r0: float, margin: float):
    """Per-filament radius from the intensity mass per unit length (voxels nearest to it)."""
    shape = raw_norm.shape
    R = r0 + margin
    lab = np.zeros(shape, np.int32)
    for k, p in enumerate(polys):
        q = _resample(p, 0.5)
        zyx = np.rint(q[:, ::-1]).astype(np.int64)
        ok = np.all((zyx >= 0) & (zyx < np.asarray(shape)), axis=1)
        zyx = zyx[ok]
        lab[zyx[:, 0], zyx[:, 1], zyx[:, 2]] = k + 1
    dist, ind = ndimage.distance_transform_edt(lab == 0, return_indices=True)
    near = dist <= R
    owner = lab[ind[0][near], ind[1][near], ind[2][near]]
    mass = np.bincount(owner, weights=np.clip(raw_norm[near], -0.5, 1.5).astype(np.float64),
                       minlength=len(polys) + 1)[1:]
    out = np.full(len(polys), r0)
    for k, p in enumerate(polys):
        L = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        r = r0
        for _ in range(4):
            r = math.sqrt(max(mass[k], 0.0) / (math.pi * max(L + 4.0 * r / 3.0, 1e-6)))
        if np.isfinite(r) and r > 0.3:
            out[k] = r
    return out


@dataclass(frozen=True)
class FilamentResult:
    """What :func:`trace_filaments` traced.

    Attributes
    ----------
    polylines : list of (m, 3) ndarray
        Centrelines ``(x, y, z)`` in working voxels, vertices about one voxel apart.
    radii : ndarray (n,)
        One radius per centreline (voxels), from its intensity mass per unit length.
    skeleton_voxels : int
        Voxels of the 3-D skeleton of the binarised volume.
    skeleton_junctions : int
        Skeleton voxels with 3 or more skeleton neighbours (removed before joining).
    branches : int
        Skeleton branches left once the junctions are removed.
    bend_fraction : float
        Share (0 to 1) of the long branches' length that bends (see :func:`bend_fraction`).
    joins : int
        Branch ends joined through junction gaps.
    faint : int
        Chains rejected because their axis is fainter than ``0.8 min_fill`` of the plateau.
    bridges : int
        Pieces joined by smooth bridges through the image (:mod:`rodwarp.ct._bridging`).
    duplicates : int
        Pieces dropped as lying along a longer filament (one skeleton for two touching ones).
    mask : ndarray of bool
        The binarised volume (reused by the confidence stage).
    """

    polylines: list
    radii: np.ndarray
    skeleton_voxels: int
    skeleton_junctions: int
    branches: int
    bend_fraction: float
    joins: int
    faint: int
    bridges: int = 0
    duplicates: int = 0
    mask: object = field(default=None, repr=False, compare=False)

    @property
    def filaments(self) -> int:
        """Number of filaments traced (``len(polylines)``)."""
        return len(self.polylines)


def trace_filaments(raw: np.ndarray, st, P, progress=None) -> FilamentResult:
    """Trace curved filaments in a (prepared, in-memory) volume.

    Parameters
    ----------
    raw : ndarray (z, y, x) float32
        The prepared volume.
    st : rodwarp.ct._levels._Levels
        Background and foreground levels, threshold, coarse radius ``r0`` (voxels).
    P : rodwarp.ct.SegmentParams
        Knobs (``smooth_sigma``, ``junction_radius``, ``min_length``, ``window_margin``).
    progress : callable(stage, done, total), optional
        Called with ``"detect"`` as the steps advance.

    Returns
    -------
    FilamentResult
        Centrelines (x, y, z) in voxels, vertices about one voxel apart, their radii
        (voxels), and the skeleton and joining counts.
    """
    from rodwarp.ct._voxels import _BlockSampler

    g = ndimage.gaussian_filter(raw, P.smooth_sigma) if P.smooth_sigma > 0 else raw
    scale = 1.0 / (st.fg_smooth - st.bg)
    g = (g - np.float32(st.bg)) * np.float32(scale)
    level = (st.threshold - st.bg) * scale
    mask = g > level
    r0 = st.r0
    sampler = _BlockSampler(g, (0, 0, 0))
    if progress is not None:
        progress("detect", 0, 3)
    branches, junc, n_sk = _branches(mask, r0, CURVED_JUNCTION * P.junction_radius)
    n_branches = len(branches)
    bend = bend_fraction(branches, max(1.5, 0.5 * r0), 6.0 * r0)
    if progress is not None:
        progress("detect", 1, 3)
    chains = _join(branches, r0, P, sampler)
    joins = int(sum(len(c) - 1 for c in chains))
    polys = []
    for ch in chains:
        p = _resample(_assemble(branches, ch), 1.0)
        L = float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
        if L < max(P.min_length * r0, 3.0):
            continue
        polys.append(_resample(_smooth(p, max(1.0, 0.5 * r0)), 1.0))
    if progress is not None:
        progress("detect", 2, 3)
    polys = _refine_centrelines(polys, sampler, r0)
    raw_norm = (raw - np.float32(st.bg)) * np.float32(1.0 / (st.fg - st.bg))
    # a filament's axis is as bright as the rods' plateau; noise blobs joined into chains are not
    keep, faint = [], 0
    for p in polys:
        ax = ndimage.map_coordinates(raw_norm, p[:, ::-1].T, order=1, mode="nearest")
        if float(np.mean(ax)) >= 0.8 * P.min_fill:
            keep.append(p)
        else:
            faint += 1
    polys = keep
    # pieces bridged through the junctions the skeleton joins missed, then duplicates dropped
    from rodwarp.ct._bridging import bridge_pieces, drop_duplicates

    support = _BlockSampler(ndimage.distance_transform_edt(~mask).astype(np.float32), (0, 0, 0))
    polys, bridges = bridge_pieces(polys, sampler, r0, BRIDGE_GAP * r0 + 6.0, BRIDGE_BEND * r0, support=support,
                                   tube=r0, trim=r0, reach=3.0 * r0)
    polys = _refine_centrelines(polys, sampler, r0, n_iter=2)
    polys, duplicates = drop_duplicates(polys, r0)
    radii = _radii(polys, raw_norm, r0, P.window_margin) if polys else np.zeros(0)
    if progress is not None:
        progress("detect", 3, 3)
    return FilamentResult(polylines=polys, radii=radii, skeleton_voxels=n_sk, skeleton_junctions=int(len(junc)),
                          branches=n_branches, bend_fraction=bend, joins=joins, faint=faint, bridges=bridges,
                          duplicates=duplicates, mask=mask)
