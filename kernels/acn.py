"""Entanglement: the Gauss linking integral of two straight segments, exactly, in float64.

For segments p1->p2 and p3->p4 the Gauss integrand's numerator (t1 x t2).(r1 - r2) has one
sign over the whole pair, so the pair's average crossing number is exactly |G| with G the
signed Gauss integral, which equals the solid angle that the "difference quadrilateral"
{p - q : p on P, q on Q} (vertices a = p1-p3, b = p2-p3, c = p2-p4, d = p1-p4) subtends
at the origin, divided by 4 pi (Banchoff 1976; Klenin & Langowski 2000).

The quadrilateral is fanned into four triangles from the foot of the perpendicular from the
origin to its plane; each triangle's solid angle uses the Van Oosterom-Strackee form
tan(Omega/2) = u.(v x w) / (|u||v||w| + (u.v)|w| + (u.w)|v| + (v.w)|u|) through atan2 (which
stays accurate in float32 where the four-arcsin form does not), with the height divided out of
numerator and denominator so nearly touching pairs keep full accuracy.

Every vertex of the quadrilateral lies at the same signed height h = (p1-p3).(e1 x e2) above
the plane through the origin, so each triangle's solid angle lies in (-2 pi, 2 pi) and
atan2 never wraps unless h is 0.  h = 0 means coplanar, collinear, parallel, touching or
degenerate segments, whose Gauss integrand vanishes everywhere it is defined: G = 0.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, TWO

wp.set_module_options({"enable_backward": False})

INV_2PI = wp.float64(0.15915494309189535)  # 1 / (2 pi)
# |h| below this fraction of |e1| |e2| |a| counts as coplanar (touching, in-plane, parallel)
COPLANAR_TOL = wp.float64(1.0e-14)


@wp.func
def fan_factor(z: wp.vec2d, num: wp.float64, vi: wp.vec3d, li: wp.float64, vj: wp.vec3d, lj: wp.float64,
               delta: wp.float64) -> wp.vec2d:
    """z times (den + i num) for the fan triangle (f, vi, vj), f = delta n_hat the foot.

    Van Oosterom-Strackee with u = f: numerator and denominator both carry a factor delta,
    divided out, so nothing of size O(delta) is formed from O(1) terms: num = n_hat.(wi x wj)
    (wi = vi - f, passed in) and den = li lj + delta (li + lj) + vi.vj (= ... + delta^2 + wi.wj).
    den > 0 (li lj >= |vi||vj|), so every factor lies in the right half plane.
    """
    den = li * lj + delta * (li + lj) + wp.dot(vi, vj)
    return wp.vec2d(z[0] * den - z[1] * num, z[0] * num + z[1] * den)


@wp.func
def gauss_linking_lengths(p1: wp.vec3d, p2: wp.vec3d, l1: wp.float64, p3: wp.vec3d, p4: wp.vec3d,
                          l2: wp.float64) -> wp.float64:
    """Signed Gauss linking integral G of segments p1->p2 and p3->p4 (|G| < 1/2).

    The pair's contribution to the average crossing number is |G|; summed with sign over
    two closed polygons it gives their linking number.  The quadrilateral a, d, c, b is
    fanned from the foot f of the perpendicular from the origin to its plane (four
    triangles), which keeps full float64 accuracy for nearly touching pairs wherever they
    cross; a two-triangle split loses about 1e-16 / gap when the crossing lies near its
    diagonal.  l1 = |p2 - p1| and l2 = |p4 - p3| are passed in, so that a caller pairing one
    segment with many computes them once.
    """
    e1 = p2 - p1
    e2 = p4 - p3
    a = p1 - p3
    n = wp.cross(e1, e2)
    h = wp.dot(a, n)
    la = wp.length(a)
    if wp.abs(h) <= COPLANAR_TOL * l1 * l2 * wp.max(la, wp.max(l1, l2)):
        return F0
    b = p2 - p3
    c = p2 - p4
    d = p1 - p4
    ln = wp.length(n)
    n_hat = n / ln
    if h < F0:
        n_hat = -n_hat
    delta = wp.abs(h) / ln
    ld = wp.length(d)
    lc = wp.length(c)
    lb = wp.length(b)
    # fan numerators n_hat.(wi x wj): consecutive vertices differ by -e2, e1, e2, -e1, and
    # n_hat.(w x e) = w.(e x n_hat) = v.(e x n_hat) (the foot is along n_hat)
    m1 = wp.cross(e1, n_hat)
    m2 = wp.cross(e2, n_hat)
    # the four half solid angles add up to Omega / 2 = 2 pi G in (-pi, pi), so the argument of
    # the product of the four factors is their sum exactly: one atan2 instead of four
    z = wp.vec2d(F1, F0)
    z = fan_factor(z, -wp.dot(a, m2), a, la, d, ld, delta)
    z = fan_factor(z, wp.dot(d, m1), d, ld, c, lc, delta)
    z = fan_factor(z, wp.dot(c, m2), c, lc, b, lb, delta)
    z = fan_factor(z, -wp.dot(b, m1), b, lb, a, la, delta)
    return wp.atan2(z[1], z[0]) * INV_2PI


@wp.func
def gauss_linking_segments(p1: wp.vec3d, p2: wp.vec3d, p3: wp.vec3d, p4: wp.vec3d) -> wp.float64:
    """Signed Gauss linking integral G of segments p1->p2 and p3->p4 (|G| < 1/2).

    The pair's contribution to the average crossing number is |G|; summed with sign over two
    closed polygons it gives their linking number.  See :func:`gauss_linking_lengths`.
    """
    return gauss_linking_lengths(p1, p2, wp.length(p2 - p1), p3, p4, wp.length(p4 - p3))


@wp.kernel
def gauss_linking_pairs(p1: wp.array(dtype=wp.vec3d), p2: wp.array(dtype=wp.vec3d), p3: wp.array(dtype=wp.vec3d),
                        p4: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    """Signed G of segment pairs (p1[i]->p2[i], p3[i]->p4[i]), one pair per thread."""
    i = wp.tid()
    out[i] = gauss_linking_segments(p1[i], p2[i], p3[i], p4[i])


@wp.kernel
def polyline_linking_rows(a: wp.array(dtype=wp.vec3d), na_edges: int, b: wp.array(dtype=wp.vec3d), nb_edges: int,
                          signed_out: wp.array(dtype=wp.float64), abs_out: wp.array(dtype=wp.float64)):
    """Row i: sum over edges j of polyline b of G and |G| with edge i of polyline a.

    Edge k of a polyline joins vertex k and vertex (k + 1) mod (vertex count), so a closed
    polygon is passed as its vertices with edges = vertex count, an open one with one fewer.
    Rows are summed on the host in a fixed order (deterministic, no atomics).
    """
    i = wp.tid()
    na = a.shape[0]
    nb = b.shape[0]
    q1 = a[i]
    q2 = a[(i + 1) % na]
    s = F0
    sa = F0
    for j in range(nb_edges):
        g = gauss_linking_segments(q1, q2, b[j], b[(j + 1) % nb])
        s += g
        sa += wp.abs(g)
    signed_out[i] = s
    abs_out[i] = sa
