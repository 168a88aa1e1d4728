"""Contact order and reuse: graph colouring of rod-rod contacts for parallel sweeps, and the
warm start of each contact from last step's impulse.

Contacts that share a vertex (hence an edge) must not be visited concurrently: on a GPU the
rod-rod contacts are coloured (``color_claim`` / ``color_commit``) and each colour is one launch.
"""

import warp as wp

from rodwarp.kernels.constants import F0

wp.set_module_options({"enable_backward": False})


@wp.func
def contact_vertices(seg: wp.array(dtype=wp.vec2i), seg_vertex: wp.array(dtype=wp.int32), k: int):
    """The four vertices contact k moves: both ends of each of its two segments."""
    ia = seg_vertex[seg[k][0]]
    ib = seg_vertex[seg[k][1]]
    return wp.vec4i(ia, ia + 1, ib, ib + 1)


@wp.kernel
def color_claim(count: int, seg: wp.array(dtype=wp.vec2i), seg_vertex: wp.array(dtype=wp.int32),
                color: wp.array(dtype=wp.int32), owner: wp.array(dtype=wp.int32)):
    """Each uncoloured contact bids for its four vertices; the lowest index wins each."""
    k = wp.tid()
    if k >= count or color[k] >= 0:
        return
    ends = contact_vertices(seg, seg_vertex, k)
    for c in range(4):
        wp.atomic_min(owner, ends[c], k)


@wp.kernel
def color_commit(count: int, seg: wp.array(dtype=wp.vec2i), seg_vertex: wp.array(dtype=wp.int32), round_id: int,
                 owner: wp.array(dtype=wp.int32), color: wp.array(dtype=wp.int32), remaining: wp.array(dtype=wp.int32)):
    """A contact that won all its vertices takes this round's colour (an independent set)."""
    k = wp.tid()
    if k >= count or color[k] >= 0:
        return
    ends = contact_vertices(seg, seg_vertex, k)
    if owner[ends[0]] == k and owner[ends[1]] == k and owner[ends[2]] == k and owner[ends[3]] == k:
        color[k] = round_id
    else:
        wp.atomic_add(remaining, 0, 1)


@wp.kernel
def warm_start_rod_contacts(count: int, key: wp.array(dtype=wp.int64), normal: wp.array(dtype=wp.vec3d), prev_count: int,
                            prev_key: wp.array(dtype=wp.int64), prev_impulse: wp.array(dtype=wp.vec3d), warm: wp.float64,
                            impulse: wp.array(dtype=wp.vec3d)):
    """Reuse last step's impulse of the same contact (keys are sorted: binary search).

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
