"""Local fields on a voxel grid: rods clipped exactly to the ball Omega_R(x) around each voxel centre.

Passes per batch of voxels, so that no kernel needs a per-thread dynamic buffer:

1. ``scatter_clipped_segments`` (count mode): per segment, the grid balls it enters with
   positive length, counted per ball;
2. ``scatter_clipped_segments`` (write mode) then ``sort_parts_by_segment``: the clipped
   parts written to a flat buffer at each ball's offset (an exclusive scan of the counts,
   done by the host), in segment order;
3. ``ball_fields``: per voxel, from its clipped parts only: rods counted, clipped length,
   clipped volume, nematic order S and the entanglement e (sum of |G| over clipped segment
   pairs of distinct rods, the exact closed form of :mod:`kernels.acn`).

``count_contacts_in_ball`` counts contact points within R of each centre.

Everything that decides a result is float64.  ``count_contacts_in_ball`` queries a hash grid
of float32 contact points with a widened radius and re-tests every candidate in float64.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF, THREE
from rodwarp.kernels.acn import gauss_linking_lengths

wp.set_module_options({"enable_backward": False})


@wp.func
def voxel_centre(v: int, nx: int, ny: int, origin: wp.vec3d, spacing: wp.float64) -> wp.vec3d:
    """Centre of voxel ``v`` (linear index, x fastest) of a grid whose voxel 0 is at ``origin``."""
    i = v % nx
    j = (v / nx) % ny
    k = v / (nx * ny)
    return origin + spacing * wp.vec3d(wp.float64(i), wp.float64(j), wp.float64(k))


@wp.func
def clip_to_ball(p0: wp.vec3d, p1: wp.vec3d, centre: wp.vec3d, radius: wp.float64) -> wp.vec2d:
    """Parameters (t0, t1) of the part of p0 + t (p1 - p0), t in [0, 1], inside the ball.

    Empty when t1 <= t0.  Uses the closest approach to the centre (t_mid) and the half chord,
    which stays accurate for short chords where the quadratic formula cancels.
    """
    d = p1 - p0
    a = wp.dot(d, d)
    if a <= F0:
        return wp.vec2d(F0, F0)
    f = p0 - centre
    t_mid = -wp.dot(f, d) / a
    q = f + t_mid * d
    h2 = radius * radius - wp.dot(q, q)
    if h2 <= F0:
        return wp.vec2d(F0, F0)
    w = wp.sqrt(h2 / a)
    t0 = wp.max(t_mid - w, F0)
    t1 = wp.min(t_mid + w, F1)
    return wp.vec2d(t0, t1)


@wp.func
def grid_range(lo: wp.float64, hi: wp.float64, origin: wp.float64, spacing: wp.float64, n: int) -> wp.vec2i:
    """Indices [i0, i1] of grid centres origin + i spacing within [lo, hi], clamped to [0, n - 1]."""
    i0 = int(wp.ceil((lo - origin) / spacing))
    i1 = int(wp.floor((hi - origin) / spacing))
    return wp.vec2i(wp.max(i0, 0), wp.min(i1, n - 1))


@wp.struct
class BallGrid:
    """The voxel grid of ball centres: nx x ny x nz points from ``origin`` at ``spacing`` (m),
    each the centre of a ball of ``radius`` (m)."""

    nx: int
    ny: int
    nz: int
    origin: wp.vec3d
    spacing: wp.float64
    radius: wp.float64


@wp.struct
class ClippedParts:
    """The segments' parts inside each ball, ball t's from ``start[t]``: ``count[t]`` of them
    (a counter while they are scattered); ends a, b, segment and rod ids, length."""

    start: wp.array(dtype=wp.int32)
    count: wp.array(dtype=wp.int32)
    a: wp.array(dtype=wp.vec3d)
    b: wp.array(dtype=wp.vec3d)
    seg: wp.array(dtype=wp.int32)
    rod: wp.array(dtype=wp.int32)
    length: wp.array(dtype=wp.float64)


@wp.kernel
def scatter_clipped_segments(p0: wp.array(dtype=wp.vec3d), p1: wp.array(dtype=wp.vec3d),
                             seg_rod: wp.array(dtype=wp.int32), grid: BallGrid, voxel_slot: wp.array(dtype=wp.int32),
                             slot_lo: int, slot_hi: int, write: int, parts: ClippedParts):
    """Segment s against every grid ball its bounding box (grown by R) reaches.

    For each ball (voxel whose slot lies in [slot_lo, slot_hi)) that the segment enters with
    positive length: with ``write == 0`` count it in parts.count[slot - slot_lo]; otherwise
    also write the clipped part at parts.start[slot - slot_lo] + (its rank from that count).  Balls are
    visited per segment rather than segments per ball: the segment's box holds few voxel
    centres, while a ball-centred hash query visits every midpoint in 27 cells.
    """
    s = wp.tid()
    a = p0[s]
    b = p1[s]
    nx = grid.nx
    ny = grid.ny
    nz = grid.nz
    origin = grid.origin
    spacing = grid.spacing
    radius = grid.radius
    rx = grid_range(wp.min(a[0], b[0]) - radius, wp.max(a[0], b[0]) + radius, origin[0], spacing, nx)
    ry = grid_range(wp.min(a[1], b[1]) - radius, wp.max(a[1], b[1]) + radius, origin[1], spacing, ny)
    rz = grid_range(wp.min(a[2], b[2]) - radius, wp.max(a[2], b[2]) + radius, origin[2], spacing, nz)
    d = b - a
    for k in range(rz[0], rz[1] + 1):
        for j in range(ry[0], ry[1] + 1):
            for i in range(rx[0], rx[1] + 1):
                v = (k * ny + j) * nx + i
                slot = int(voxel_slot[v])
                if slot < slot_lo or slot >= slot_hi:
                    continue
                c = origin + spacing * wp.vec3d(wp.float64(i), wp.float64(j), wp.float64(k))
                tt = clip_to_ball(a, b, c, radius)
                if tt[1] > tt[0]:
                    t = slot - slot_lo
                    rank = wp.atomic_add(parts.count, t, wp.int32(1))
                    if write != 0:
                        w = int(parts.start[t]) + int(rank)
                        ca = a + tt[0] * d
                        cb = a + tt[1] * d
                        parts.a[w] = ca
                        parts.b[w] = cb
                        parts.length[w] = wp.length(cb - ca)
                        parts.seg[w] = wp.int32(s)
                        parts.rod[w] = seg_rod[s]


@wp.kernel
def sort_parts_by_segment(start: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32),
                          clip_a: wp.array(dtype=wp.vec3d), clip_b: wp.array(dtype=wp.vec3d),
                          clip_seg: wp.array(dtype=wp.int32), clip_rod: wp.array(dtype=wp.int32),
                          clip_len: wp.array(dtype=wp.float64)):
    """Insertion sort of each ball's parts by segment id: a fixed summation order on every device
    (parallel atomics write them in any order; on one CPU thread they arrive sorted, O(k))."""
    t = wp.tid()
    b = int(start[t])
    m = int(count[t])
    for i in range(1, m):
        key = clip_seg[b + i]
        j = i - 1
        if clip_seg[b + j] > key:
            ka = clip_a[b + i]
            kb = clip_b[b + i]
            kr = clip_rod[b + i]
            kl = clip_len[b + i]
            while j >= 0:
                if clip_seg[b + j] <= key:
                    break
                clip_a[b + j + 1] = clip_a[b + j]
                clip_b[b + j + 1] = clip_b[b + j]
                clip_seg[b + j + 1] = clip_seg[b + j]
                clip_rod[b + j + 1] = clip_rod[b + j]
                clip_len[b + j + 1] = clip_len[b + j]
                j -= 1
            clip_a[b + j + 1] = ka
            clip_b[b + j + 1] = kb
            clip_seg[b + j + 1] = key
            clip_rod[b + j + 1] = kr
            clip_len[b + j + 1] = kl


@wp.kernel
def ball_fields(parts: ClippedParts, seg_diameter: wp.array(dtype=wp.float64), rods_out: wp.array(dtype=wp.int32),
                length_out: wp.array(dtype=wp.float64), volume_out: wp.array(dtype=wp.float64),
                order_out: wp.array(dtype=wp.float64), entanglement_out: wp.array(dtype=wp.float64)):
    """Per voxel t, from its clipped parts: rods, length, rod volume, S and e.

    rods: distinct rod ids among the parts.  volume: sum of (pi d^2 / 4) L.  S: largest
    eigenvalue of the length-weighted Q = <(3 u u^T - I) / 2> (NaN when the ball holds no
    rod).  e: sum of |G| over part pairs of distinct rods (pairs within one rod excluded).
    """
    t = wp.tid()
    b = int(parts.start[t])
    m = int(parts.count[t])
    clip_a = parts.a
    clip_b = parts.b
    clip_seg = parts.seg
    clip_rod = parts.rod
    clip_len = parts.length
    rods = int(0)
    total = F0
    vol = F0
    uu = wp.mat33d()
    ent = F0
    for i in range(m):
        ai = clip_a[b + i]
        bi = clip_b[b + i]
        ri = clip_rod[b + i]
        d = bi - ai
        L = clip_len[b + i]
        total += L
        dia = seg_diameter[int(clip_seg[b + i])]
        vol += wp.float64(0.7853981633974483) * dia * dia * L
        # L u u^T = d d^T / L
        uu += wp.outer(d, d) / L
        first = int(1)
        for j in range(i):
            if clip_rod[b + j] == ri:
                first = 0
        rods += first
        for j in range(i + 1, m):
            if clip_rod[b + j] != ri:
                ent += wp.abs(gauss_linking_lengths(ai, bi, L, clip_a[b + j], clip_b[b + j], clip_len[b + j]))
    rods_out[t] = wp.int32(rods)
    length_out[t] = total
    volume_out[t] = vol
    entanglement_out[t] = ent
    if total > F0:
        ident = wp.identity(n=3, dtype=wp.float64)
        qt = (THREE * uu / total - ident) * HALF
        evecs, evals = wp.eig3(qt)
        order_out[t] = wp.max(evals[0], wp.max(evals[1], evals[2]))
    else:
        order_out[t] = wp.float64(wp.nan)


@wp.kernel
def count_contacts_in_ball(grid: wp.uint64, voxels: wp.array(dtype=wp.int32), nx: int, ny: int, origin: wp.vec3d,
                           spacing: wp.float64, radius: wp.float64, query_radius: float,
                           points: wp.array(dtype=wp.vec3d), count: wp.array(dtype=wp.int32)):
    """count[t]: contact points within distance R of voxel voxels[t]'s centre."""
    t = wp.tid()
    c = voxel_centre(int(voxels[t]), nx, ny, origin, spacing)
    q = wp.hash_grid_query(grid, wp.vec3(float(c[0]), float(c[1]), float(c[2])), query_radius)
    s = int(0)
    m = int(0)
    r2 = radius * radius
    while wp.hash_grid_query_next(q, s):
        dx = points[s] - c
        if wp.dot(dx, dx) <= r2:
            m += 1
    count[t] = wp.int32(m)
