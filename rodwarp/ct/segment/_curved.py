"""Curved filaments (wires, fibres, arcs) traced as polylines from a greyscale CT volume.

Used by :func:`rodwarp.ct.segment_volume` with ``shape="curved"`` (or ``"auto"`` when
the skeleton's branches bend).  Inputs are the prepared volume and the global levels of the
straight-rod pipeline; coordinates are ``(x, y, z)`` in working voxels.

Pipeline (:func:`trace_filaments`):

1. **skeleton** -- Gaussian denoising, binarisation at the half level, 3-D skeleton; voxels
   near a junction (a skeleton voxel with 3 or more neighbours: where filaments touch or
   cross) are removed, so the skeleton falls apart into *branches*, each a simple path ordered
   by the geodesic distance from one of its ends and averaged per unit of that distance.
2. **centreline** -- each branch is resampled every voxel, smoothed along its length, and
   refined against the greyscale: every vertex moves to the intensity centroid of the disc
   normal to the branch, ignoring voxels nearer to another branch (so touching filaments do
   not pull each other), then smoothed again.
3. **joining** -- branch ends are paired through the junction gaps by a minimum-cost matching
   of smooth bridges the image supports (:func:`rodwarp.ct.segment._bridging.pair_ends`); chains of
   paired branches are filaments, refined once more as wholes; faint chains (noise) and
   duplicates (one skeleton drawn for two touching filaments) are dropped.
4. **on the foreground** -- filaments are trimmed where their ends run off the binarised
   foreground and cut where their axis leaves it for more than :data:`OFF_RUN` radii (a bridge
   across a gap); what is left mostly off it goes (:func:`_split_off_foreground`).
5. **second pass** -- the foreground farther than ``r0 + 1.5`` from every filament (thick
   fibres, fused masses, pieces cut short at knots: what a tracer built for radius ``r0``
   leaves out) is split into regions; each large region's longest skeleton path becomes a
   filament (:func:`_residual_filaments`), a few rounds.  Their radii come from their own
   mass, as below; the confidence stage flags those wider than thick
   (:mod:`rodwarp.ct.segment._doubt`).
6. **radius** -- per filament, from the intensity mass per unit length (voxels assigned to
   their nearest filament), which blur does not change: ``mass = C pi r^2 (L + 4 r / 3)``.
7. **contacts** -- pairs of *distinct* filaments whose surfaces come within the contact
   tolerance (pieces of one filament are one filament, so never in contact with each other).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from rodwarp.ct._voxels import _resample


__all__ = ["trace_filaments", "bend_fraction", "FilamentResult"]

#: the junction neighbourhood removed is this share of the straight path's (``junction_radius``):
#: smaller gaps to bridge (chosen on development seeds of the wire tangle, filament F1)
CURVED_JUNCTION = 0.5
#: longest bridge between pieces: this many radii plus 6 voxels
BRIDGE_GAP = 8.0
#: a piece's end for the pairing is taken this many radii inside its last vertex (the
#: pairing's default is one radius; half a radius paired touching wires of radius 1.5-2 a
#: little better on development seeds 1000-1007 of ``rodwarp.testing.ct_generator.wire_tangle(
#: touching=True)``: filament F1 mean 0.852 -> 0.863 at r 1.5, 0.953 -> 0.969 at r 2)
BRIDGE_TRIM = 0.5


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
    from rodwarp.ct.segment._seeds import _components, _skeleton

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


#: a filament is cut where its axis runs off the binarised foreground for more than this many
#: radii (and at least 3 voxels): every trace then lies on the foreground
OFF_RUN = 1.5
#: second pass: foreground farther than this many voxels from every trace's surface is residual
RESIDUAL_MARGIN = 1.5
#: second pass: a residual region is traced when it holds at least this many cross-sections'
#: worth of voxels (pi r0^2 per voxel of length, this many radii long)
RESIDUAL_MIN_RADII = 4.0
#: second pass: at most this many rounds (each traces one path per residual region)
RESIDUAL_ROUNDS = 3


def _on_mask(mask: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Nearest-voxel mask values at polyline vertices (x, y, z); False outside the volume."""
    zyx = np.rint(p[:, ::-1]).astype(np.int64)
    ok = np.all((zyx >= 0) & (zyx < np.asarray(mask.shape)), axis=1)
    out = np.zeros(len(p), bool)
    out[ok] = mask[zyx[ok, 0], zyx[ok, 1], zyx[ok, 2]]
    return out


def _split_off_foreground(polys, mask, r0: float, min_len: float):
    """Cut every filament where its axis leaves the foreground for more than ``OFF_RUN`` radii;
    the off-foreground runs are dropped, and pieces shorter than ``min_len`` with them.

    Returns (pieces, cuts)."""
    run_max = max(3.0, OFF_RUN * r0)
    out, cuts = [], 0
    for p in polys:
        q = _resample(p, 1.0) if len(p) >= 2 else p
        on = _on_mask(mask, q)
        if on.all() or len(q) < 3:
            out.append(p)
            continue
        # runs of off-foreground vertices
        pad = np.concatenate([[True], on, [True]])
        d = np.diff(pad.astype(np.int8))
        starts, ends = np.flatnonzero(d == -1), np.flatnonzero(d == 1)
        bad = np.zeros(len(q), bool)
        for a, b in zip(starts, ends):
            if b - a > run_max or a == 0 or b == len(q):
                bad[a:b] = True
        if not bad.any():
            out.append(p)
            continue
        cuts += 1
        pad = np.concatenate([[True], bad, [True]])
        d = np.diff(pad.astype(np.int8))
        for a, b in zip(np.flatnonzero(d == -1), np.flatnonzero(d == 1)):
            piece = q[a:b]
            if len(piece) >= 2 and float(np.linalg.norm(np.diff(piece, axis=0), axis=1).sum()) >= min_len:
                out.append(piece)
    # what is left mostly off the foreground (short gaps adding up) goes too
    kept = []
    for p in out:
        if _on_mask(mask, _resample(p, 1.0) if len(p) >= 2 else p).mean() >= 0.9:
            kept.append(p)
        else:
            cuts += 1
    return kept, cuts


def _longest_path(pts: np.ndarray, pairs: np.ndarray) -> np.ndarray:
    """The longest geodesic path through a (branched) skeleton: its voxels in order (m, 3)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import dijkstra

    n = len(pts)
    if n < 2 or len(pairs) == 0:
        return pts[:1]
    w = np.linalg.norm(pts[pairs[:, 0]] - pts[pairs[:, 1]], axis=1)
    g = coo_matrix((w, (pairs[:, 0], pairs[:, 1])), shape=(n, n)).tocsr()
    d0 = dijkstra(g, directed=False, indices=0)
    d0[~np.isfinite(d0)] = -1
    a = int(np.argmax(d0))
    d, pred = dijkstra(g, directed=False, indices=a, return_predecessors=True)
    d[~np.isfinite(d)] = -1
    b = int(np.argmax(d))
    path = [b]
    while path[-1] != a and pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    return pts[np.array(path[::-1])]


def _residual_filaments(polys, mask, r0: float, min_len: float):
    """The second pass: centrelines of the foreground no first-pass filament explains.

    The foreground farther than ``r0 + RESIDUAL_MARGIN`` from every filament's axis is split into
    connected regions; each region large enough (:data:`RESIDUAL_MIN_RADII`) is skeletonised,
    and its longest geodesic skeleton path, smoothed, becomes a filament when it is at least ``min_len``
    long and lies on the foreground.  These are the thick fibres and fused masses the first pass
    (built for fibres of radius ``r0``) leaves out; their radii come from their own intensity mass
    and the confidence stage judges them like any other trace (a fused mass is wider than thick).
    """
    from skimage.morphology import skeletonize

    from rodwarp.ct.segment._seeds import _components

    lab = np.zeros(mask.shape, np.int32)
    for k, p in enumerate(polys):
        q = _resample(p, 0.5)
        zyx = np.rint(q[:, ::-1]).astype(np.int64)
        ok = np.all((zyx >= 0) & (zyx < np.asarray(mask.shape)), axis=1)
        zyx = zyx[ok]
        lab[zyx[:, 0], zyx[:, 1], zyx[:, 2]] = 1
    dist = ndimage.distance_transform_edt(lab == 0)
    res = mask & (dist > r0 + RESIDUAL_MARGIN)
    if not res.any():
        return []
    # regions: opened a little, so that a thin fringe along a traced fibre is no region
    res = ndimage.binary_opening(res, structure=ndimage.generate_binary_structure(3, 1))
    cc, n = ndimage.label(res, structure=np.ones((3, 3, 3), bool))
    if n == 0:
        return []
    sizes = np.bincount(cc.ravel(), minlength=n + 1)
    min_vox = max(27, int(math.pi * r0 * r0 * RESIDUAL_MIN_RADII * r0))
    out = []
    objs = ndimage.find_objects(cc)
    for k in range(1, n + 1):
        if sizes[k] < min_vox or objs[k - 1] is None:
            continue
        sl = objs[k - 1]
        sub = np.pad(cc[sl] == k, 1)
        sk = np.argwhere(skeletonize(sub)) - 1 + np.array([s.start for s in sl])
        if len(sk) < 3:
            continue
        pairs = _components(sk)[0]
        path = _longest_path(sk[:, ::-1].astype(np.float64), pairs)
        if len(path) < 3:
            continue
        path = _resample(path, 1.0)
        if len(path) >= 5:
            path = _resample(_smooth(path, max(1.0, 0.5 * r0)), 1.0)
        if float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum()) < min_len:
            continue
        if _on_mask(mask, path).mean() < 0.9:
            continue
        out.append(path)
    return out


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
    faint : int
        Filaments rejected because their axis is fainter than ``0.8 min_fill`` of the plateau.
    bridges : int
        Branch ends joined by smooth bridges through the junction gaps (:mod:`rodwarp.ct.segment._bridging`).
    duplicates : int
        Pieces dropped as lying along a longer filament (one skeleton for two touching ones).
    off_foreground_cuts : int
        Filaments trimmed or cut where their axis left the binarised foreground (at an end, or
        for more than :data:`OFF_RUN` radii: a bridge across a gap, a trace through noise), or
        dropped as mostly off it.
    residual : int
        Filaments traced in the second pass, from foreground the first pass left more than
        :data:`RESIDUAL_MARGIN` voxels from every trace (thick fibres, fused masses, pieces cut
        short at knots); the last ``residual`` polylines.
    mask : ndarray of bool
        The binarised volume (reused by the confidence stage).
    """

    polylines: list
    radii: np.ndarray
    skeleton_voxels: int
    skeleton_junctions: int
    branches: int
    bend_fraction: float
    faint: int
    bridges: int = 0
    duplicates: int = 0
    mask: object = field(default=None, repr=False, compare=False)
    off_foreground_cuts: int = 0
    residual: int = 0

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
    st : rodwarp.ct.segment._levels._Levels
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
    # every branch is refined on its own first: its ends then point where the filament goes,
    # not towards the junction it was cut from
    pieces = [_resample(b, 1.0) for b in branches]
    pieces = [_resample(_smooth(p, max(1.0, 0.5 * r0)), 1.0) if len(p) >= 5 else p for p in pieces]
    pieces = _refine_centrelines(pieces, sampler, r0)
    from rodwarp.ct.segment._bridging import drop_duplicates, pair_ends

    polys, bridges = pair_ends(pieces, sampler, r0, BRIDGE_GAP * r0 + 6.0, trim=BRIDGE_TRIM * r0)
    polys = [p for p in polys if float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())
             >= max(P.min_length * r0, 3.0)]
    if progress is not None:
        progress("detect", 2, 3)
    polys = _refine_centrelines(polys, sampler, r0, n_iter=2)
    raw_norm = (raw - np.float32(st.bg)) * np.float32(1.0 / (st.fg - st.bg))
    # a filament's axis is as bright as the rods' plateau; noise blobs joined into chains are not
    keep, faint = [], 0
    for p in polys:
        ax = ndimage.map_coordinates(raw_norm, p[:, ::-1].T, order=1, mode="nearest")
        if float(np.mean(ax)) >= 0.8 * P.min_fill:
            keep.append(p)
        else:
            faint += 1
    polys, duplicates = drop_duplicates(keep, r0)
    min_len = max(P.min_length * r0, 3.0)
    polys, cut = _split_off_foreground(polys, mask, r0, min_len)
    extra = []
    for _ in range(RESIDUAL_ROUNDS):  # a branched mass gives one path a round
        more = _residual_filaments(polys + extra, mask, r0, min_len) if polys else []
        extra += more
        if not more:
            break
    polys = polys + extra
    radii = _radii(polys, raw_norm, r0, P.window_margin) if polys else np.zeros(0)
    if progress is not None:
        progress("detect", 3, 3)
    return FilamentResult(polylines=polys, radii=radii, skeleton_voxels=n_sk, skeleton_junctions=int(len(junc)),
                          branches=n_branches, bend_fraction=bend, faint=faint, bridges=bridges,
                          duplicates=duplicates, mask=mask, off_foreground_cuts=cut, residual=len(extra))
