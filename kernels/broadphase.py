"""Broadphase: segment midpoints in a Warp HashGrid, candidate pairs within reach.

Two segments can only be closer than ``margin`` when their midpoints are within
h_a / 2 + h_b / 2 + r_a + r_b + margin, so one hash-grid query of that radius around each
midpoint finds every candidate; the cost is linear in the number of segments.
"""

import warp as wp

from rodwarp.kernels.narrowphase import closest_points_segments
from rodwarp.kernels.structs import RodModel

wp.set_module_options({"enable_backward": False})


@wp.kernel
def segment_midpoints(seg_vertex: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec3d), mid: wp.array(dtype=wp.vec3)):
    s = wp.tid()
    i = seg_vertex[s]
    m = (x[i] + x[i + 1]) * wp.float64(0.5)
    mid[s] = wp.vec3(wp.float32(m[0]), wp.float32(m[1]), wp.float32(m[2]))


@wp.kernel
def max_speed(v: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    """out[0] = max |v| and out[1] = 1 when any velocity is not finite."""
    i = wp.tid()
    s = wp.length(v[i])
    if wp.isnan(s) or wp.isinf(s):
        out[1] = wp.float64(1.0)
    else:
        wp.atomic_max(out, 0, s)


@wp.func
def within_reach(model: RodModel, sa: int, sb: int, mid: wp.array(dtype=wp.vec3), x: wp.array(dtype=wp.vec3d),
                 r2: float, margin: wp.float64):
    """Whether segments sa and sb belong in the Verlet list: capsule gap below ``margin``.

    Two segments of one rod less than a diameter of arc length apart never form a contact:
    they could touch only if the rod bent to a radius below its own, and with edges shorter
    than a diameter they overlap in the rod's rest shape (the pair would push the rod apart
    along its own axis)."""
    # the grid returns whole cells, most of them out of reach
    dm = mid[sb] - mid[sa]
    if wp.dot(dm, dm) > r2:
        return False
    ia = model.seg_vertex[sa]
    ib = model.seg_vertex[sb]
    ra = model.vertex_rod[ia]
    rb = model.vertex_rod[ib]
    if rb == ra:
        lo = wp.min(ia, ib)
        hi = wp.max(ia, ib)
        # the arc length strictly between the two segments
        if model.arc[hi] - model.arc[lo + 1] < model.radius[ra] + model.radius[rb]:
            return False
    # the distance between the two infinite lines bounds the segments' from below: a cheap
    # reject of most pairs of long (rigid) rods, which the midpoint test alone keeps
    da = x[ia + 1] - x[ia]
    db = x[ib + 1] - x[ib]
    c = wp.cross(da, db)
    cc = wp.dot(c, c)
    if cc > wp.float64(1.0e-12) * wp.dot(da, da) * wp.dot(db, db):
        if wp.abs(wp.dot(x[ib] - x[ia], c)) / wp.sqrt(cc) - model.radius[ra] - model.radius[rb] > margin:
            return False
    # exact capsule gap: only pairs that can come within reach are kept
    pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
    return pair.dist - model.radius[ra] - model.radius[rb] <= margin


@wp.kernel
def stale_segments(seg_vertex: wp.array(dtype=wp.int32), x: wp.array(dtype=wp.vec3d), sums: wp.array(dtype=wp.vec3d),
                   inv_count: wp.float64, ref: wp.array(dtype=wp.vec3d), tau: wp.float64,
                   flag: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32), stale: wp.array(dtype=wp.int32)):
    """flag[s] = 1 for every segment that has moved by more than ``tau`` since its last
    refresh (either end point: no point of the segment has moved further), listed in
    ``stale`` (in any order: the contacts are sorted by key later). Positions are measured
    from the pile's mean position now, sums[0] * inv_count (``ref`` holds them from the mean
    at the last refresh): a common translation changes no distance between segments, so the
    list holds in whatever frame it is measured, and a falling or tossed pile stays fresh."""
    s = wp.tid()
    i = seg_vertex[s]
    o = sums[0] * inv_count
    d = wp.max(wp.length(x[i] - o - ref[2 * s]), wp.length(x[i + 1] - o - ref[2 * s + 1]))
    if d > tau:
        flag[s] = 1
        k = wp.atomic_add(count, 0, 1)
        stale[k] = s
    else:
        flag[s] = 0


@wp.kernel
def drop_pairs_of_flagged(pairs: wp.array(dtype=wp.vec2i), flag: wp.array(dtype=wp.int32),
                          out: wp.array(dtype=wp.vec2i), count: wp.array(dtype=wp.int32)):
    """The pairs that involve no flagged segment, compacted (in any order)."""
    p = pairs[wp.tid()]
    if flag[p[0]] == 0 and flag[p[1]] == 0:
        out[wp.atomic_add(count, 0, 1)] = p


@wp.kernel
def find_pairs_of_flagged(grid: wp.uint64, stale: wp.array(dtype=wp.int32), flag: wp.array(dtype=wp.int32),
                          mid: wp.array(dtype=wp.vec3), model: RodModel, x: wp.array(dtype=wp.vec3d),
                          query_radius: float, margin: wp.float64, capacity: int, count: wp.array(dtype=wp.int32),
                          pairs: wp.array(dtype=wp.vec2i), sums: wp.array(dtype=wp.vec3d), inv_count: wp.float64,
                          ref: wp.array(dtype=wp.vec3d)):
    """Broadphase (Verlet list): every pair of a flagged segment whose capsule gap is below
    ``margin`` (contact margin + skin) now, found through the hash grid (midpoints within
    ``query_radius`` = h_max + 2 r_max + margin); a pair of two flagged segments once, from
    the lower one, appended as (lower, higher); the flagged segment's reference moves to its
    present position (from the pile's mean position, :func:`stale_segments`). A full build flags every
    segment; a partial refresh those that moved."""
    sa = stale[wp.tid()]
    r2 = query_radius * query_radius
    query = wp.hash_grid_query(grid, mid[sa], query_radius)
    sb = int(0)
    while wp.hash_grid_query_next(query, sb):
        if sb == sa or (flag[sb] != 0 and sb < sa):
            continue
        if within_reach(model, sa, sb, mid, x, r2, margin):
            k = wp.atomic_add(count, 0, 1)
            if k < capacity:
                pairs[k] = wp.vec2i(wp.min(sa, sb), wp.max(sa, sb))
    i = model.seg_vertex[sa]
    o = sums[0] * inv_count
    ref[2 * sa] = x[i] - o
    ref[2 * sa + 1] = x[i + 1] - o
