"""Contact generation (rod-rod and rod-plane) and warm starting from the previous step.

Rod-rod contacts are speculative: a segment pair becomes a contact when its capsule gap is
below ``margin`` (contact distance plus the distance both segments can travel in one step),
and the solver only forbids the gap from closing below zero during the step.  That is what
prevents tunnelling at large steps.
"""

import warp as wp

from rodwarp.kernels.narrowphase import closest_points_segments

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)
F1 = wp.float64(1.0)


@wp.kernel
def find_candidate_pairs(
    grid: wp.uint64,
    mid: wp.array(dtype=wp.vec3),
    seg_vertex: wp.array(dtype=wp.int32),
    vertex_rod: wp.array(dtype=wp.int32),
    rod_radius: wp.array(dtype=wp.float64),
    x: wp.array(dtype=wp.vec3d),
    query_radius: float,
    margin: wp.float64,
    capacity: int,
    count: wp.array(dtype=wp.int32),
    pairs: wp.array(dtype=wp.vec2i),
):
    """Broadphase (Verlet list): every pair sa < sb whose capsule gap is below ``margin``
    (contact margin + skin), found through the hash grid (midpoints within
    ``query_radius`` = h_max + 2 r_max + margin).  The list stays valid until some vertex has
    moved by half the skin."""
    sa = wp.tid()
    ia = seg_vertex[sa]
    ra = vertex_rod[ia]
    ma = mid[sa]
    r2 = query_radius * query_radius
    query = wp.hash_grid_query(grid, ma, query_radius)
    sb = int(0)
    while wp.hash_grid_query_next(query, sb):
        if sb <= sa:
            continue
        # the grid returns whole cells, most of them out of reach
        dm = mid[sb] - ma
        if wp.dot(dm, dm) > r2:
            continue
        ib = seg_vertex[sb]
        rb = vertex_rod[ib]
        if rb == ra and (ib == ia + 1 or ia == ib + 1):
            continue
        # exact capsule gap at build time: only pairs that can come within reach are kept
        pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
        if pair.dist - rod_radius[ra] - rod_radius[rb] > margin:
            continue
        k = wp.atomic_add(count, 0, 1)
        if k < capacity:
            pairs[k] = wp.vec2i(sa, sb)


@wp.kernel
def narrowphase_pairs(
    pairs: wp.array(dtype=wp.vec2i),
    n_pairs: int,
    nseg: int,
    seg_vertex: wp.array(dtype=wp.int32),
    vertex_rod: wp.array(dtype=wp.int32),
    rod_radius: wp.array(dtype=wp.float64),
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    base_margin: wp.float64,
    dt: wp.float64,
    capacity: int,
    count: wp.array(dtype=wp.int32),
    c_seg: wp.array(dtype=wp.vec2i),
    c_key: wp.array(dtype=wp.int64),
    c_st: wp.array(dtype=wp.vec2d),
    c_normal: wp.array(dtype=wp.vec3d),
    c_gap: wp.array(dtype=wp.float64),
):
    """Narrowphase: exact capsule gap of each candidate pair; a contact when it is below
    the contact distance plus what both segments can close in one step (speculative)."""
    k = wp.tid()
    if k >= n_pairs:
        return
    sa = pairs[k][0]
    sb = pairs[k][1]
    ia = seg_vertex[sa]
    ib = seg_vertex[sb]
    pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
    gap = pair.dist - rod_radius[vertex_rod[ia]] - rod_radius[vertex_rod[ib]]
    va = wp.max(wp.length(v[ia]), wp.length(v[ia + 1]))
    vb = wp.max(wp.length(v[ib]), wp.length(v[ib + 1]))
    if gap < base_margin + (va + vb) * dt:
        c = wp.atomic_add(count, 0, 1)
        if c < capacity:
            c_seg[c] = wp.vec2i(sa, sb)
            c_key[c] = wp.int64(sa) * wp.int64(nseg) + wp.int64(sb)
            c_st[c] = wp.vec2d(pair.s, pair.t)
            c_normal[c] = pair.normal
            c_gap[c] = gap


@wp.kernel
def max_displacement(x: wp.array(dtype=wp.vec3d), x_ref: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    wp.atomic_max(out, 0, wp.length(x[i] - x_ref[i]))


@wp.kernel
def iota(out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = i


@wp.kernel
def gather_contacts(
    order: wp.array(dtype=wp.int32),
    count: int,
    seg_in: wp.array(dtype=wp.vec2i),
    st_in: wp.array(dtype=wp.vec2d),
    normal_in: wp.array(dtype=wp.vec3d),
    gap_in: wp.array(dtype=wp.float64),
    seg_out: wp.array(dtype=wp.vec2i),
    st_out: wp.array(dtype=wp.vec2d),
    normal_out: wp.array(dtype=wp.vec3d),
    gap_out: wp.array(dtype=wp.float64),
):
    k = wp.tid()
    if k >= count:
        return
    j = order[k]
    seg_out[k] = seg_in[j]
    st_out[k] = st_in[j]
    normal_out[k] = normal_in[j]
    gap_out[k] = gap_in[j]


@wp.kernel
def warm_start_rod_contacts(
    count: int,
    key: wp.array(dtype=wp.int64),
    normal: wp.array(dtype=wp.vec3d),
    prev_count: int,
    prev_key: wp.array(dtype=wp.int64),
    prev_impulse: wp.array(dtype=wp.vec3d),
    warm: wp.float64,
    impulse: wp.array(dtype=wp.vec3d),
):
    """Reuse last step's impulse of the same segment pair (keys are sorted: binary search).

    The old impulse is split along the new normal; its tangential part is kept, as friction
    that held last step should hold from the first iteration of this one.
    """
    k = wp.tid()
    if k >= count:
        return
    target = key[k]
    lo = int(0)
    hi = prev_count
    while lo < hi:
        mid = (lo + hi) // 2
        if prev_key[mid] < target:
            lo = mid + 1
        else:
            hi = mid
    p = wp.vec3d(F0, F0, F0)
    if lo < prev_count:
        if prev_key[lo] == target:
            old = prev_impulse[lo]
            n = normal[k]
            pn = wp.max(wp.dot(old, n), F0)
            pt = old - n * wp.dot(old, n)
            p = (n * pn + pt) * warm
    impulse[k] = p


@wp.kernel
def contact_overlap(
    count: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    vertex_rod: wp.array(dtype=wp.int32),
    rod_radius: wp.array(dtype=wp.float64),
    x: wp.array(dtype=wp.vec3d),
    gap_out: wp.array(dtype=wp.float64),
    out: wp.array(dtype=wp.float64),
):
    """Capsule gap of every detected pair at positions ``x``; out[0] = deepest overlap (m)."""
    k = wp.tid()
    if k >= count:
        return
    ia = seg_vertex[seg[k][0]]
    ib = seg_vertex[seg[k][1]]
    pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
    g = pair.dist - rod_radius[vertex_rod[ia]] - rod_radius[vertex_rod[ib]]
    gap_out[k] = g
    wp.atomic_max(out, 0, -g)
