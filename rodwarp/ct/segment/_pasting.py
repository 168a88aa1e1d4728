"""Stage ``merge`` of segmentation, pasting: pieces of one rod joined, duplicate fits of one rod made one.

Contacts, gaps and chunk borders cut a rod into collinear pieces; two pieces are pasted when
their axes agree and the image shows the gap between them filled (:func:`_gap_filler`), and
a piece whose axis lies mostly within 0.75 r of another's is a duplicate of it (distinct rods,
even touching ones, keep their axes 2 r apart).
"""

from __future__ import annotations

import math

import numpy as np

from rodwarp.ct._voxels import _basis, _disc_offsets, _point_segment_distance
from rodwarp.rodset import segment_distance


def _merge_lines(lines, r, angle_deg, dist, gap, dup_radius=0.75, dup_fraction=0.5, filled=None):
    """Union pieces of one rod; returns (merged [(p0, p1)], number of unions, groups).

    Two pieces belong to one rod when either

    * (duplicate) at least ``dup_fraction`` of the shorter one's axis lies within
      ``dup_radius * r`` of the longer one's segment (two distinct rods, even touching ones,
      keep their axes at least 2 r apart), or
    * (pasting) they differ by at most ``angle_deg``, the shorter one's ends lie within
      ``dist`` of the longer one's line, and the gap between their extents along that line is
      at most ``gap`` (and, when there is a gap and ``filled(p, q)`` is given, the image is
      foreground all along it: two collinear rods end to end stay apart).

    A group's line is the principal axis of points spread along all its members (each member
    weighted by its length); its extent covers every member.
    """
    from scipy.spatial import cKDTree

    n = len(lines)
    if n == 0:
        return [], 0, []
    P0 = np.array([l[0] for l in lines], dtype=np.float64)
    P1 = np.array([l[1] for l in lines], dtype=np.float64)
    L = np.linalg.norm(P1 - P0, axis=1)
    U = (P1 - P0) / np.maximum(L, 1e-12)[:, None]
    mid = 0.5 * (P0 + P1)
    parent = np.arange(n)

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    nm = 0
    if n > 1:
        reach = float(L.max()) + gap + dist + 2 * r
        pairs = cKDTree(mid).query_pairs(reach, output_type="ndarray")
        if len(pairs):  # only pairs whose segments come close can be one rod
            d = segment_distance(P0[pairs[:, 0]], P1[pairs[:, 0]], P0[pairs[:, 1]], P1[pairs[:, 1]])
            pairs = pairs[d <= max(dist, dup_radius * r, gap) + 1e-9]
        cos_paste = math.cos(math.radians(angle_deg))
        for i, j in pairs:
            c = abs(U[i] @ U[j])
            a, b = (i, j) if (L[i], -i) >= (L[j], -j) else (j, i)
            if np.linalg.norm(mid[a] - mid[b]) > 0.5 * (L[a] + L[b]) + gap + dist + 2 * r:
                continue
            same = False
            ns = max(2, int(math.ceil(L[b])) + 1)
            q = P0[b] + np.linspace(0.0, 1.0, ns)[:, None] * (P1[b] - P0[b])
            # two distinct rods cannot keep their axes within r of each other: coverage decides
            # (whatever the angle: short pieces have unreliable directions)
            dq = _point_segment_distance(q, P0[a], P1[a])
            if np.mean(dq <= dup_radius * r) >= dup_fraction or dq[len(dq) // 2] <= dup_radius * r:
                # (or its middle lies inside the longer one's body: no genuine rod can)
                same = True
            elif c >= cos_paste:
                w = np.stack([P0[b], P1[b]]) - P0[a]
                t = w @ U[a]
                perp = np.linalg.norm(w - t[:, None] * U[a], axis=1)
                if perp.max() <= dist:
                    g = max(t.min() - L[a], -t.max(), 0.0)
                    same = g <= gap
                    if same and g > 0.5 and filled is not None:
                        if t.min() > L[a]:
                            pa, pb = P1[a], np.stack([P0[b], P1[b]])[int(np.argmin(t))]
                        else:
                            pa, pb = P0[a], np.stack([P0[b], P1[b]])[int(np.argmax(t))]
                        same = bool(filled(pa, pb))
            if same:
                ri, rj = find(i), find(j)
                if ri != rj:
                    parent[max(ri, rj)] = min(ri, rj)
                    nm += 1
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(find(k), []).append(k)
    out, members = [], []
    for root in sorted(groups):
        mem = groups[root]
        members.append(mem)
        if len(mem) == 1:
            out.append((P0[mem[0]].copy(), P1[mem[0]].copy()))
            continue
        # members at an angle to the longest one (junk fitted across the rod, or a fragment
        # with a poor direction) are absorbed without shaping the line
        ref = mem[int(np.argmax(L[mem]))]
        cos_keep = math.cos(math.radians(max(angle_deg, 10.0)))
        mem = [k for k in mem if abs(U[k] @ U[ref]) >= cos_keep]
        pts = np.concatenate([P0[k] + np.linspace(0.0, 1.0, max(2, int(math.ceil(L[k])) + 1))[:, None]
                              * (P1[k] - P0[k]) for k in mem])
        c = pts.mean(0)
        _, _, vt = np.linalg.svd(pts - c, full_matrices=False)
        u = vt[0]
        ends = np.concatenate([P0[mem], P1[mem]])
        t = (ends - c) @ u
        out.append((c + t.min() * u, c + t.max() * u))
    return out, nm, members


def _gap_filler(reader, st, r):
    """filled(p, q): True when the normalised intensity, averaged over a small disc, stays at
    or above one half all along the segment p-q (a rod continues there)."""
    disc = _disc_offsets(min(1.5, 0.5 * r), 0.5)
    scale = 1.0 / (st.fg - st.bg)

    def filled(p, q):
        d = q - p
        L = float(np.linalg.norm(d))
        if L < 1e-9:
            return True
        u = d / L
        e1, e2 = _basis(u)
        ss = np.linspace(0.0, L, max(2, int(math.ceil(L / 0.5)) + 1))
        pts = p + ss[:, None, None] * u + disc[None, :, 0, None] * e1 + disc[None, :, 1, None] * e2
        v = (reader.trilinear(pts.reshape(-1, 3)) - st.bg) * scale
        v = v.reshape(len(ss), len(disc))
        ok = np.all(np.isfinite(v), axis=1)
        if not ok.any():
            return False
        return bool(np.nanmean(v[ok], axis=1).min() >= 0.5)

    return filled
