"""Narrowphase: robust closest points between two segments (capsule axes), in float64.

``closest_points_segments(p0, p1, q0, q1)`` minimises |P(s) - Q(t)| over s, t in [0, 1] with
P(s) = p0 + s (p1 - p0) and Q(t) = q0 + t (q1 - q0).

Numerics
    The pair is first moved to a local frame (origin p0), so large absolute offsets
    (coordinates ~1e3 with unit segments) cost no accuracy; the distance is computed in that
    frame.  When the pair's size L (largest coordinate of p1, q0, q1 relative to p0) lies
    outside [1e-50, 1e50] the frame is also divided by L, so squares and the fourth powers
    in |dP x dQ|^2 never overflow or underflow; ordinary inputs are not rescaled (exact
    results stay exact).  All tolerances are relative to L.

Cases
    * general position: unclamped line-line solution from cross products (no a e - b^2
      cancellation), then clamp s, project onto Q, clamp t and re-project onto P
      (Ericson, "Real-Time Collision Detection", 5.1.9), which is exact for a convex
      quadratic over the unit square.  When the closest points of the two lines lie on both
      segments, distance and normal come from projecting pa - pb on dP x dQ, so the normal
      is exactly perpendicular to both segments even for near-touching crossings;
    * parallel / anti-parallel / collinear (|dP x dQ|^2 <= 1e-12 |dP|^2 |dQ|^2): s is the
      middle of the overlap of Q's projection on P (a single, stable contact for
      side-by-side rods), or the nearest end of P when they do not overlap; t is the
      clamped projection of P(s) on Q.  For nearly parallel pairs (angle theta <= 1e-6) this
      overestimates the true minimum by at most min(theta |dP|, (theta |dP|)^2 / (2 dist));
    * degenerate segments (length <= 1e-14 L) use their midpoint (s or t = 0.5), which
      reduces to point-segment or point-point.

Normal
    ``normal`` is the unit vector from ``pb`` (on Q) toward ``pa`` (on P).  When the distance
    is 0 or below 1e-14 of the scale (L or the largest absolute coordinate, whichever is
    larger) it is normalize(dP x dQ), turned to point from Q's midpoint side to P's midpoint
    side when that is decided; for parallel (or degenerate) pairs it is a deterministic unit
    vector perpendicular to dP (to dQ when P is degenerate).  No output is ever NaN.
"""

import numpy as np
import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF
from rodwarp.kernels.structs import RawContacts, RodModel

wp.set_module_options({"enable_backward": False})

PARALLEL_TOL = wp.float64(1.0e-12)  # on sin^2 of the angle between the segments
DEGENERATE_TOL = wp.float64(1.0e-28)  # on squared length relative to the pair's size
CONTACT_TOL = wp.float64(1.0e-14)  # distance treated as zero, relative to the scale
SCALE_LO = wp.float64(1.0e-50)
SCALE_HI = wp.float64(1.0e50)


@wp.struct
class SegmentPair:
    s: wp.float64
    t: wp.float64
    pa: wp.vec3d
    pb: wp.vec3d
    normal: wp.vec3d
    dist: wp.float64


@wp.func
def _max_abs(v: wp.vec3d):
    return wp.max(wp.abs(v[0]), wp.max(wp.abs(v[1]), wp.abs(v[2])))


@wp.func
def any_perpendicular(v: wp.vec3d):
    """Deterministic unit vector perpendicular to v ((0, 0, 1) when v is zero)."""
    result = wp.vec3d(F0, F0, F1)
    m = _max_abs(v)
    if m > F0:
        u = v / m
        ax = wp.abs(u[0])
        ay = wp.abs(u[1])
        az = wp.abs(u[2])
        axis = wp.vec3d(F1, F0, F0)
        if ay < ax and ay <= az:
            axis = wp.vec3d(F0, F1, F0)
        elif az < ax and az < ay:
            axis = wp.vec3d(F0, F0, F1)
        c = wp.cross(u, axis)
        result = c / wp.length(c)
    return result


@wp.func
def closest_points_segments(p0: wp.vec3d, p1: wp.vec3d, q0: wp.vec3d, q1: wp.vec3d) -> SegmentPair:
    """Closest points of segments p0-p1 (parameter s) and q0-q1 (parameter t)."""
    # local frame: origin p0, size L (rescaled only for extreme L)
    lp1 = p1 - p0
    lq0 = q0 - p0
    lq1 = q1 - p0
    size = wp.max(_max_abs(lp1), wp.max(_max_abs(lq0), _max_abs(lq1)))
    coord = wp.max(_max_abs(p0), wp.max(_max_abs(p1), wp.max(_max_abs(q0), _max_abs(q1))))
    # rescale only when squares could under/overflow, so ordinary inputs stay exact
    inv = F1
    if size > F0 and (size > SCALE_HI or size < SCALE_LO):
        inv = F1 / size
    ls = size * inv  # size of the pair in the working frame
    ls2 = ls * ls
    d1 = lp1 * inv
    d2 = (q1 - q0) * inv
    w = lq0 * inv  # q0 - p0
    a = wp.dot(d1, d1)
    e = wp.dot(d2, d2)
    b = wp.dot(d1, d2)
    deg_p = a <= DEGENERATE_TOL * ls2
    deg_q = e <= DEGENERATE_TOL * ls2
    n = wp.cross(d1, d2)
    nn = wp.dot(n, n)
    parallel = True
    interior = False
    s = HALF
    t = HALF
    if deg_p and deg_q:
        s = HALF
        t = HALF
    elif deg_p:
        s = HALF
        t = wp.clamp(wp.dot(d1 * HALF - w, d2) / e, F0, F1)
    elif deg_q:
        t = HALF
        s = wp.clamp(wp.dot(w + d2 * HALF, d1) / a, F0, F1)
    elif nn <= PARALLEL_TOL * a * e:
        # (anti-)parallel: middle of the overlap of Q's projection on P, else nearest end
        sq0 = wp.dot(w, d1) / a
        sq1 = wp.dot(w + d2, d1) / a
        lo = wp.max(F0, wp.min(sq0, sq1))
        hi = wp.min(F1, wp.max(sq0, sq1))
        if lo <= hi:
            s = HALF * (lo + hi)
        elif wp.max(sq0, sq1) < F0:
            s = F0
        else:
            s = F1
        t = wp.clamp(wp.dot(d1 * s - w, d2) / e, F0, F1)
    else:
        parallel = False
        s_line = wp.dot(wp.cross(w, d2), n) / nn
        s = wp.clamp(s_line, F0, F1)
        t = (b * s - wp.dot(d2, w)) / e
        if t < F0:
            t = F0
            s = wp.clamp(wp.dot(w, d1) / a, F0, F1)
        elif t > F1:
            t = F1
            s = wp.clamp((b + wp.dot(w, d1)) / a, F0, F1)
        else:
            interior = s == s_line  # closest points of the two lines lie on both segments

    diff = d1 * s - (w + d2 * t)  # pa - pb in the working frame
    ldiff = wp.length(diff)
    direction = wp.vec3d(F0, F0, F0)
    if interior:
        # pa - pb is along dP x dQ: project on it, which removes the rounding of s and t
        # from both the distance and the normal (exactly perpendicular to both segments)
        nhat = n / wp.sqrt(nn)
        h = wp.dot(diff, nhat)
        ldiff = wp.abs(h)
        direction = nhat
        if h < F0:
            direction = -nhat
    elif ldiff > F0:
        direction = diff / ldiff
    pair = SegmentPair()
    pair.s = s
    pair.t = t
    pair.pa = p0 + lp1 * s
    pair.pb = q0 + (q1 - q0) * t
    pair.dist = ldiff / inv
    tol = CONTACT_TOL * wp.max(ls, coord * inv)
    if ldiff > tol:
        pair.normal = direction
    elif not parallel:
        nrm = n / wp.sqrt(nn)
        side = wp.dot(nrm, d1 * HALF - (w + d2 * HALF))  # midpoint P - midpoint Q
        if side < F0:
            nrm = -nrm
        pair.normal = nrm
    elif not deg_p:
        pair.normal = any_perpendicular(d1)
    else:
        pair.normal = any_perpendicular(d2)
    return pair


@wp.func
def capsule_gap(pair: SegmentPair, ra: wp.float64, rb: wp.float64) -> wp.float64:
    """Surface gap of two capsules (negative when they overlap)."""
    return pair.dist - ra - rb


@wp.func
def segment_reach(v: wp.array(dtype=wp.vec3d), i: int, dt: wp.float64):
    return wp.max(wp.length(v[i]), wp.length(v[i + 1])) * dt


@wp.func
def point_to_segment(p: wp.vec3d, q0: wp.vec3d, q1: wp.vec3d):
    """Parameter of the point of segment q0-q1 nearest to p."""
    d = q1 - q0
    e = wp.dot(d, d)
    t = HALF
    if e > F0:
        t = wp.clamp(wp.dot(p - q0, d) / e, F0, F1)
    return t


@wp.kernel
def narrowphase_pairs(pairs: wp.array(dtype=wp.vec2i), n_pairs: int, nseg: int, model: RodModel,
                      x: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d), base_margin: wp.float64, dt: wp.float64,
                      out: RawContacts):
    """Narrowphase: exact capsule gap of each candidate pair; a contact when it is below the
    contact distance plus what both segments can close in one step (speculative).

    Side-by-side segments touch along a line, which one point cannot hold (a rigid rod would
    pivot about it): when both ends of the overlap of Q's projection on P are within reach
    too, and at least a radius from the closest point, they become contacts of their own.
    Keys (sa * S + sb) * 3 + (0 closest, 1, 2 line ends) identify contacts across steps.
    """
    k = wp.tid()
    if k >= n_pairs:
        return
    sa = pairs[k][0]
    sb = pairs[k][1]
    ia = model.seg_vertex[sa]
    ib = model.seg_vertex[sb]
    ra = model.radius[model.vertex_rod[ia]]
    rb = model.radius[model.vertex_rod[ib]]
    reach = base_margin + segment_reach(v, ia, dt) + segment_reach(v, ib, dt)
    # the infinite lines' distance bounds the segments' from below: most candidates stop here
    da = x[ia + 1] - x[ia]
    db = x[ib + 1] - x[ib]
    cr = wp.cross(da, db)
    cc = wp.dot(cr, cr)
    if cc > wp.float64(1.0e-12) * wp.dot(da, da) * wp.dot(db, db):
        if wp.abs(wp.dot(x[ib] - x[ia], cr)) / wp.sqrt(cc) - ra - rb >= reach:
            return
    pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
    gap = pair.dist - ra - rb
    if gap >= reach:
        return
    key = (wp.int64(sa) * wp.int64(nseg) + wp.int64(sb)) * wp.int64(3)
    c = wp.atomic_add(out.count, 0, 1)
    if c < out.capacity:
        out.seg[c] = wp.vec2i(sa, sb)
        out.key[c] = key
        out.st[c] = wp.vec2d(pair.s, pair.t)
        out.normal[c] = pair.normal
        out.gap[c] = gap
    # line contact: the two ends of the overlap
    p0 = x[ia]
    d1 = x[ia + 1] - p0
    a = wp.dot(d1, d1)
    if a <= F0:
        return
    sq0 = wp.dot(x[ib] - p0, d1) / a
    sq1 = wp.dot(x[ib + 1] - p0, d1) / a
    lo = wp.max(F0, wp.min(sq0, sq1))
    hi = wp.min(F1, wp.max(sq0, sq1))
    la = wp.sqrt(a)
    if (hi - lo) * la < wp.float64(2.0) * (ra + rb):
        return
    for end in range(2):
        s = lo
        if end == 1:
            s = hi
        if wp.abs(s - pair.s) * la < ra + rb:
            continue
        pa = p0 + d1 * s
        t = point_to_segment(pa, x[ib], x[ib + 1])
        diff = pa - (x[ib] + (x[ib + 1] - x[ib]) * t)
        dist = wp.length(diff)
        g = dist - ra - rb
        if g >= reach or dist <= F0:
            continue
        c = wp.atomic_add(out.count, 0, 1)
        if c < out.capacity:
            out.seg[c] = wp.vec2i(sa, sb)
            out.key[c] = key + wp.int64(1 + end)
            out.st[c] = wp.vec2d(s, t)
            out.normal[c] = diff / dist
            out.gap[c] = g


@wp.kernel
def iota(out: wp.array(dtype=wp.int32)):
    i = wp.tid()
    out[i] = i


@wp.kernel
def gather_contacts(order: wp.array(dtype=wp.int32), count: int, seg_in: wp.array(dtype=wp.vec2i),
                    st_in: wp.array(dtype=wp.vec2d), normal_in: wp.array(dtype=wp.vec3d),
                    gap_in: wp.array(dtype=wp.float64), seg_out: wp.array(dtype=wp.vec2i),
                    st_out: wp.array(dtype=wp.vec2d), normal_out: wp.array(dtype=wp.vec3d),
                    gap_out: wp.array(dtype=wp.float64)):
    k = wp.tid()
    if k >= count:
        return
    j = order[k]
    seg_out[k] = seg_in[j]
    st_out[k] = st_in[j]
    normal_out[k] = normal_in[j]
    gap_out[k] = gap_in[j]


@wp.kernel
def contact_overlap(count: int, seg: wp.array(dtype=wp.vec2i), seg_vertex: wp.array(dtype=wp.int32),
                    vertex_rod: wp.array(dtype=wp.int32), rod_radius: wp.array(dtype=wp.float64),
                    x: wp.array(dtype=wp.vec3d), gap_out: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    """Capsule gap of every detected segment pair at positions ``x`` into ``gap_out`` (per
    contact point); out[0] = deepest overlap (m). With an empty ``gap_out`` (the step's
    check) a line contact's extra points, which follow their pair's first (contacts are
    sorted by key), are skipped: one pair, one gap."""
    k = wp.tid()
    if k >= count:
        return
    sp = seg[k]
    keep = gap_out.shape[0] > 0
    if k > 0 and not keep:
        if seg[k - 1] == sp:
            return
    ia = seg_vertex[sp[0]]
    ib = seg_vertex[sp[1]]
    pair = closest_points_segments(x[ia], x[ia + 1], x[ib], x[ib + 1])
    g = pair.dist - rod_radius[vertex_rod[ia]] - rod_radius[vertex_rod[ib]]
    if keep:
        gap_out[k] = g
    wp.atomic_max(out, 0, -g)


@wp.kernel
def closest_points_kernel(p0: wp.array(dtype=wp.vec3d), p1: wp.array(dtype=wp.vec3d), q0: wp.array(dtype=wp.vec3d),
                          q1: wp.array(dtype=wp.vec3d), out_s: wp.array(dtype=wp.float64),
                          out_t: wp.array(dtype=wp.float64), out_dist: wp.array(dtype=wp.float64),
                          out_normal: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    pair = closest_points_segments(p0[i], p1[i], q0[i], q1[i])
    out_s[i] = pair.s
    out_t[i] = pair.t
    out_dist[i] = pair.dist
    out_normal[i] = pair.normal


def closest_points(p0, p1, q0, q1, device="cpu"):
    """Host helper: evaluate many pairs; returns numpy arrays s, t, dist, normal, pa, pb."""
    from rodwarp import _warp

    _warp.init()
    arrs = [np.ascontiguousarray(np.asarray(v, dtype=np.float64).reshape(-1, 3)) for v in (p0, p1, q0, q1)]
    n = arrs[0].shape[0]
    if any(v.shape[0] != n for v in arrs):
        raise ValueError("p0, p1, q0, q1 must have the same number of points")
    ins = [wp.array(v, dtype=wp.vec3d, device=device) for v in arrs]
    s = wp.zeros(n, dtype=wp.float64, device=device)
    t = wp.zeros(n, dtype=wp.float64, device=device)
    dist = wp.zeros(n, dtype=wp.float64, device=device)
    normal = wp.zeros(n, dtype=wp.vec3d, device=device)
    if n > 0:
        wp.launch(closest_points_kernel, dim=n, inputs=[*ins, s, t, dist, normal], device=device)
    s_np, t_np = s.numpy(), t.numpy()
    return {
        "s": s_np,
        "t": t_np,
        "dist": dist.numpy(),
        "normal": normal.numpy(),
        "pa": arrs[0] + s_np[:, None] * (arrs[1] - arrs[0]),
        "pb": arrs[2] + t_np[:, None] * (arrs[3] - arrs[2]),
    }
