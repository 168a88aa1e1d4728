"""Clearance of candidate rods against placed rods, for random sequential addition."""

import warp as wp

from rodwarp.kernels.narrowphase import closest_points_segments

wp.set_module_options({"enable_backward": False})


@wp.kernel
def candidate_clearance(grid: wp.uint64, pa: wp.array(dtype=wp.vec3d), pb: wp.array(dtype=wp.vec3d),
                        ca: wp.array(dtype=wp.vec3d), cb: wp.array(dtype=wp.vec3d), reach: float, diameter: wp.float64,
                        out: wp.array(dtype=wp.float64)):
    """Per candidate segment: smallest surface gap (m) to any placed segment within reach."""
    k = wp.tid()
    m = (ca[k] + cb[k]) * wp.float64(0.5)
    q = wp.hash_grid_query(grid, wp.vec3(wp.float32(m[0]), wp.float32(m[1]), wp.float32(m[2])), reach)
    best = wp.float64(1.0e300)
    j = int(0)
    while wp.hash_grid_query_next(q, j):
        pair = closest_points_segments(ca[k], cb[k], pa[j], pb[j])
        best = wp.min(best, pair.dist - diameter)
    out[k] = best
