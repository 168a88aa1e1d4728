"""Broadphase: segment midpoints in a Warp HashGrid, candidate pairs within reach.

Two segments can only be closer than ``margin`` when their midpoints are within
h_a / 2 + h_b / 2 + r_a + r_b + margin, so one hash-grid query of that radius around each
midpoint finds every candidate; the cost is linear in the number of segments.
"""

import warp as wp

from rodwarp.kernels.narrowphase import closest_points_segments

wp.set_module_options({"enable_backward": False})


@wp.kernel
def segment_midpoints(
    seg_vertex: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    mid: wp.array(dtype=wp.vec3),
):
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


@wp.kernel
def max_displacement(x: wp.array(dtype=wp.vec3d), x_ref: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    i = wp.tid()
    wp.atomic_max(out, 0, wp.length(x[i] - x_ref[i]))


@wp.kernel
def find_candidate_pairs(
    grid: wp.uint64,
    mid: wp.array(dtype=wp.vec3),
    seg_vertex: wp.array(dtype=wp.int32),
    vertex_rod: wp.array(dtype=wp.int32),
    rod_radius: wp.array(dtype=wp.float64),
    arc: wp.array(dtype=wp.float64),
    x: wp.array(dtype=wp.vec3d),
    query_radius: float,
    margin: wp.float64,
    capacity: int,
    count: wp.array(dtype=wp.int32),
    pairs: wp.array(dtype=wp.vec2i),
):
    """Broadphase (Verlet list): every pair sa < sb whose capsule gap is below ``margin``
    (contact margin + skin), found through the hash grid (midpoints within
    ``query_radius`` = h_max + 2 r_max + margin). The list stays valid until some vertex has
    moved by half the skin.

    Two segments of one rod less than a diameter of arc length apart never form a contact:
    they could touch only if the rod bent to a radius below its own, and with edges shorter
    than a diameter they overlap in the rod's rest shape (the pair would push the rod apart
    along its own axis)."""
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
        if rb == ra:
            # sb > sa, so ib > ia: the arc length strictly between the two segments
            if arc[ib] - arc[ia + 1] < rod_radius[ra] + rod_radius[rb]:
                continue
        # the distance between the two infinite lines bounds the segments' from below: a cheap
        # reject of most pairs of long (rigid) rods, which the midpoint test alone keeps
        da = x[ia + 1] - x[ia]
        db = x[ib + 1] - x[ib]
        c = wp.cross(da, db)
        cc = wp.dot(c, c)
        if cc > wp.float64(1.0e-12) * wp.dot(da, da) * wp.dot(db, db):
            if wp.abs(wp.dot(x[ib] - x[ia], c)) / wp.sqrt(cc) - rod_radius[ra] - rod_radius[rb] > margin:
                continue
        # exact capsule gap at build time: only pairs that can come within reach are kept
        pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
        if pair.dist - rod_radius[ra] - rod_radius[rb] > margin:
            continue
        k = wp.atomic_add(count, 0, 1)
        if k < capacity:
            pairs[k] = wp.vec2i(sa, sb)
