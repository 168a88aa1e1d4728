"""Stage ``detect`` of segmentation, seeding: straight pieces of the 3-D skeleton of the binarised rods.

Junctions of the skeleton (voxels with 3 or more skeleton neighbours, where rods touch or
cross) are removed with a ball of about one radius around each, so that branches at contacts
separate; each remaining branch, ordered along its path and split where it bends
(Douglas-Peucker), is a seed: a centre, a direction and an extent.  How much of the skeleton
bends decides ``shape="auto"``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rodwarp.ct.segment._params import SegmentParams
from rodwarp.ct._voxels import _canonical


@dataclass(frozen=True)
class SeedResult:
    """What :func:`_skeleton_seeds` found in one block.

    Attributes
    ----------
    seeds : list of (centre, direction, t0, t1, n)
        Straight skeleton pieces, longest first: ``centre`` (3,) in block ``(x, y, z)`` voxels,
        ``direction`` a unit (3,) vector, ``t0 <= t1`` the extent along it (voxels) and ``n``
        the number of skeleton voxels in the piece.
    skeleton_voxels : int
        Voxels of the 3-D skeleton of the binarised block, before junctions are removed.
    skeleton_junctions : int
        Skeleton voxels with 3 or more skeleton neighbours.
    branch_voxels : int
        Voxels of the long branches (at least 8 coarse radii) judged for bending.
    bent_voxels : int
        Voxels of those long branches that bend smoothly (a curve, not two straight rods
        meeting at a corner).
    bent_branches : int
        Number of such smoothly bending branches.
    """

    seeds: list
    skeleton_voxels: int
    skeleton_junctions: int
    branch_voxels: int = 0
    bent_voxels: int = 0
    bent_branches: int = 0


def _dp_split(q: np.ndarray, tol: float) -> list[tuple[int, int]]:
    """Douglas-Peucker: index ranges [a, b] of an ordered polyline whose points stay within tol of the chord."""
    out = []
    stack = [(0, len(q) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            out.append((a, b))
            continue
        d = q[b] - q[a]
        L = float(np.linalg.norm(d))
        w = q[a + 1:b] - q[a]
        if L > 0:
            dist = np.linalg.norm(w - np.outer(w @ d / (L * L), d), axis=1)
        else:
            dist = np.linalg.norm(w, axis=1)
        i = int(np.argmax(dist))
        if dist[i] <= tol:
            out.append((a, b))
        else:
            m = a + 1 + i
            stack.append((m, b))
            stack.append((a, m))
    out.sort()
    return out


def _skeleton(mask: np.ndarray, r0: float, junction_radius: float):
    """The 3-D skeleton of ``mask`` with its junctions cut out.

    Returns
    -------
    idx : (m, 3) int
        Skeleton voxels (z, y, x).
    junc : (j, 3) int
        Junctions: skeleton voxels with 3 or more skeleton neighbours (where rods touch or cross).
    keep : (m,) bool
        Skeleton voxels farther than ``junction_radius * r0 + 1`` from every junction, so that
        the branches of touching rods come apart.
    """
    from scipy.spatial import cKDTree
    from skimage.morphology import skeletonize

    idx = np.argwhere(skeletonize(mask))
    if len(idx) == 0:
        return idx, idx, np.zeros(0, bool)
    nb = cKDTree(idx).query_ball_point(idx, 1.75, return_length=True) - 1
    junc = idx[nb >= 3]
    keep = np.ones(len(idx), bool)
    if len(junc):
        d, _ = cKDTree(junc).query(idx, distance_upper_bound=junction_radius * r0 + 1.0 + 1e-6)
        keep = ~np.isfinite(d)
    return idx, junc, keep


def _components(pts: np.ndarray):
    """Connected pieces of a set of voxels (26-neighbours: centres within 1.75 voxels).

    Returns
    -------
    (pairs, graph, n_components, labels, order, bounds)
        ``pairs`` (p, 2) neighbouring voxel indices, ``graph`` their sparse adjacency (COO);
        component k holds the voxels ``order[bounds[k]:bounds[k + 1]]``.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from scipy.spatial import cKDTree

    pairs = cKDTree(pts).query_pairs(1.75, output_type="ndarray")
    n = len(pts)
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n)) if len(pairs) else \
        coo_matrix((n, n))
    ncomp, lab = connected_components(g, directed=False)
    order = np.argsort(lab, kind="stable")
    bounds = np.searchsorted(lab[order], np.arange(ncomp + 1))
    return pairs, g, ncomp, lab, order, bounds


def _skeleton_seeds(mask: np.ndarray, r0: float, P: SegmentParams, cut_faces=None) -> SeedResult:
    """Straight skeleton pieces, junction neighbourhoods removed, and how much of the skeleton bends.

    ``cut_faces``: per axis (z, y, x) a pair of flags, True where the block face is interior to
    the volume (a chunk border): the skeleton bends along such faces, so voxels near them are
    dropped (the neighbouring chunk sees those parts of the rods).
    """
    from scipy.sparse.csgraph import breadth_first_order

    idx, junc, keep = _skeleton(mask, r0, P.junction_radius)
    if len(idx) == 0:
        return SeedResult([], 0, 0)
    if cut_faces is not None:
        m = r0 + 1.0
        for ax in range(3):
            lo_cut, hi_cut = cut_faces[ax]
            if lo_cut:
                keep &= idx[:, ax] >= m
            if hi_cut:
                keep &= idx[:, ax] <= mask.shape[ax] - 1 - m
    pts = idx[keep]
    if len(pts) == 0:
        return SeedResult([], len(idx), len(junc))
    pairs, g, ncomp, lab, order, bounds = _components(pts)
    csr = g.tocsr()
    csr = csr + csr.T
    deg = np.diff(csr.indptr)
    tol = max(1.5, 0.5 * r0)
    seeds = []
    bend_stats = [0, 0, 0]
    for k in range(ncomp):
        mem = order[bounds[k]:bounds[k + 1]]
        if len(mem) < P.min_seed_voxels:
            continue
        q = pts[mem][:, ::-1].astype(np.float64)  # xyz
        pieces = [np.arange(len(mem))]
        if len(mem) > 2 * P.min_seed_voxels:
            # a branch may run from one rod into another without a junction (an end touching a
            # side, a block face): order it along the path and split it where it bends
            start = mem[np.lexsort((mem, deg[mem]))[0]]
            path = breadth_first_order(csr, start, directed=False, return_predecessors=False)
            pos = {int(v): i for i, v in enumerate(mem)}
            ordered = np.array([pos[int(v)] for v in path if int(v) in pos])
            pieces = [ordered[a:b + 1] for a, b in _dp_split(q[ordered], tol)]
        if len(mem) >= 8.0 * r0:  # for shape="auto": how much of the skeleton bends
            # (a tolerance of a radius, at least 2 voxels: noise and thin rods wiggle less)
            bend_stats[0] += len(mem)
            pc2 = _dp_split(q[ordered], max(2.0, r0)) if len(pieces) > 1 else []
            if len(pc2) > 1:
                # a skeleton path from one straight rod into another (a crossing, an end on a
                # side) is two chords meeting at a sharp corner; a curve needs more chords, or
                # turns gently between two
                d = np.array([q[ordered[b]] - q[ordered[a]] for a, b in pc2])
                d /= np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
                turn = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", d[1:], d[:-1]), -1.0, 1.0)))
                if len(pc2) >= 3 or turn.max() < 20.0:
                    bend_stats[1] += len(mem)
                    bend_stats[2] += 1
        for idx_p in pieces:
            if len(idx_p) < P.min_seed_voxels:
                continue
            qq = q[idx_p]
            c = qq.mean(0)
            _, _, vt = np.linalg.svd(qq - c, full_matrices=False)
            u = _canonical(vt[0])
            t = (qq - c) @ u
            seeds.append((c, u, float(t.min()), float(t.max()), len(idx_p)))
    # longest first; ties broken by position (deterministic)
    seeds.sort(key=lambda s: (-(s[3] - s[2]), -s[4], tuple(np.round(s[0], 6))))
    return SeedResult(seeds, len(idx), len(junc), *bend_stats)
