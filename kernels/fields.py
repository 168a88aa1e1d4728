"""Local fields on a voxel grid: rods clipped exactly to the ball Omega_R(x) around each voxel centre.

Three passes per batch of voxels, so that no kernel needs a per-thread dynamic buffer:

1. ``count_clipped_segments``: per voxel, the segments whose clipped part has positive length
   (candidates from the hash grid of segment midpoints);
2. ``gather_clipped_segments``: the clipped parts written to a flat buffer at the voxel's
   offset (an exclusive scan of the counts, done by the host);
3. ``ball_fields``: per voxel, from its clipped parts only: rods counted, clipped length,
   clipped volume, nematic order S and the entanglement e (sum of |G| over clipped segment
   pairs of distinct rods, the exact closed form of :mod:`kernels.acn`).

``count_contacts_in_ball`` counts contact points within R of each centre.

Everything that decides a result is float64.  The hash grid stores float32 midpoints, so the
query radius carries a margin and every candidate is re-tested exactly in float64.
"""

import warp as wp

from rodwarp.kernels.acn import gauss_linking_lengths

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)
F1 = wp.float64(1.0)
HALF = wp.float64(0.5)
THREE = wp.float64(3.0)


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


@wp.kernel
def count_clipped_segments(
    grid: wp.uint64,
    voxels: wp.array(dtype=wp.int32),
    nx: int,
    ny: int,
    origin: wp.vec3d,
    spacing: wp.float64,
    radius: wp.float64,
    query_radius: float,
    p0: wp.array(dtype=wp.vec3d),
    p1: wp.array(dtype=wp.vec3d),
    count: wp.array(dtype=wp.int32),
):
    """count[t]: segments with a clipped part of positive length in the ball of voxel voxels[t]."""
    t = wp.tid()
    c = voxel_centre(int(voxels[t]), nx, ny, origin, spacing)
    q = wp.hash_grid_query(grid, wp.vec3(float(c[0]), float(c[1]), float(c[2])), query_radius)
    s = int(0)
    m = int(0)
    while wp.hash_grid_query_next(q, s):
        tt = clip_to_ball(p0[s], p1[s], c, radius)
        if tt[1] > tt[0]:
            m += 1
    count[t] = wp.int32(m)


@wp.kernel
def gather_clipped_segments(
    grid: wp.uint64,
    voxels: wp.array(dtype=wp.int32),
    nx: int,
    ny: int,
    origin: wp.vec3d,
    spacing: wp.float64,
    radius: wp.float64,
    query_radius: float,
    p0: wp.array(dtype=wp.vec3d),
    p1: wp.array(dtype=wp.vec3d),
    seg_rod: wp.array(dtype=wp.int32),
    start: wp.array(dtype=wp.int32),
    clip_a: wp.array(dtype=wp.vec3d),
    clip_b: wp.array(dtype=wp.vec3d),
    clip_seg: wp.array(dtype=wp.int32),
    clip_rod: wp.array(dtype=wp.int32),
    clip_len: wp.array(dtype=wp.float64),
):
    """The clipped parts of voxel voxels[t]'s ball, written from start[t] on (same order as counted)."""
    t = wp.tid()
    c = voxel_centre(int(voxels[t]), nx, ny, origin, spacing)
    q = wp.hash_grid_query(grid, wp.vec3(float(c[0]), float(c[1]), float(c[2])), query_radius)
    s = int(0)
    w = int(start[t])
    while wp.hash_grid_query_next(q, s):
        tt = clip_to_ball(p0[s], p1[s], c, radius)
        if tt[1] > tt[0]:
            d = p1[s] - p0[s]
            ca = p0[s] + tt[0] * d
            cb = p0[s] + tt[1] * d
            clip_a[w] = ca
            clip_b[w] = cb
            clip_len[w] = wp.length(cb - ca)
            clip_seg[w] = wp.int32(s)
            clip_rod[w] = seg_rod[s]
            w += 1


@wp.kernel
def ball_fields(
    start: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
    clip_a: wp.array(dtype=wp.vec3d),
    clip_b: wp.array(dtype=wp.vec3d),
    clip_seg: wp.array(dtype=wp.int32),
    clip_rod: wp.array(dtype=wp.int32),
    clip_len: wp.array(dtype=wp.float64),
    seg_diameter: wp.array(dtype=wp.float64),
    rods_out: wp.array(dtype=wp.int32),
    length_out: wp.array(dtype=wp.float64),
    volume_out: wp.array(dtype=wp.float64),
    order_out: wp.array(dtype=wp.float64),
    entanglement_out: wp.array(dtype=wp.float64),
):
    """Per voxel t, from its clipped parts: rods, length, rod volume, S and e.

    rods: distinct rod ids among the parts.  volume: sum of (pi d^2 / 4) L.  S: largest
    eigenvalue of the length-weighted Q = <(3 u u^T - I) / 2> (NaN when the ball holds no
    rod).  e: sum of |G| over part pairs of distinct rods (pairs within one rod excluded).
    """
    t = wp.tid()
    b = int(start[t])
    m = int(count[t])
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
def count_contacts_in_ball(
    grid: wp.uint64,
    voxels: wp.array(dtype=wp.int32),
    nx: int,
    ny: int,
    origin: wp.vec3d,
    spacing: wp.float64,
    radius: wp.float64,
    query_radius: float,
    points: wp.array(dtype=wp.vec3d),
    count: wp.array(dtype=wp.int32),
):
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
