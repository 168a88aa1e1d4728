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
def find_rod_contacts(
    grid: wp.uint64,
    mid: wp.array(dtype=wp.vec3),
    seg_vertex: wp.array(dtype=wp.int32),
    vertex_rod: wp.array(dtype=wp.int32),
    rod_radius: wp.array(dtype=wp.float64),
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    query_radius: float,
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
    """One thread per segment ``sa``: every partner ``sb > sa`` closer than its margin."""
    sa = wp.tid()
    ia = seg_vertex[sa]
    ra = vertex_rod[ia]
    pa0 = x[ia]
    pa1 = x[ia + 1]
    va = wp.max(wp.length(v[ia]), wp.length(v[ia + 1]))
    rada = rod_radius[ra]
    nseg = mid.shape[0]
    query = wp.hash_grid_query(grid, mid[sa], query_radius)
    sb = int(0)
    while wp.hash_grid_query_next(query, sb):
        if sb <= sa:
            continue
        ib = seg_vertex[sb]
        rb = vertex_rod[ib]
        if rb == ra and (ib == ia + 1 or ia == ib + 1):
            continue
        pair = closest_points_segments(pa0, pa1, x[ib], x[ib + 1])
        gap = pair.dist - rada - rod_radius[rb]
        vb = wp.max(wp.length(v[ib]), wp.length(v[ib + 1]))
        margin = base_margin + (va + vb) * dt
        if gap < margin:
            k = wp.atomic_add(count, 0, 1)
            if k < capacity:
                c_seg[k] = wp.vec2i(sa, sb)
                c_key[k] = wp.int64(sa) * wp.int64(nseg) + wp.int64(sb)
                c_st[k] = wp.vec2d(pair.s, pair.t)
                c_normal[k] = pair.normal
                c_gap[k] = gap


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
