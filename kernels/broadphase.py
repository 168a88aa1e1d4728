"""Broadphase: segment midpoints in a Warp HashGrid, candidate pairs within reach.

Two segments can only be closer than ``margin`` when their midpoints are within
h_a / 2 + h_b / 2 + r_a + r_b + margin, so one hash-grid query of that radius around each
midpoint finds every candidate; the cost is linear in the number of segments.
"""

import warp as wp

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
