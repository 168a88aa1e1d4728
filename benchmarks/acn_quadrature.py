"""Gauss linking integral of segment pairs by tensor Gauss-Legendre quadrature (float64).

Benchmark peer only: rodwarp itself uses the exact closed form of :mod:`rodwarp.kernels.acn`.
This is what a quadrature implementation of the average crossing number computes,

    G = 1/(4 pi) int_0^1 int_0^1 (e1 x e2).(r1(s) - r2(t)) / |r1(s) - r2(t)|^3 ds dt,

r1(s) = p1 + s e1, r2(t) = p3 + t e2, with a q x q tensor Gauss-Legendre rule on [0, 1]^2.
Nodes and weights (already mapped to [0, 1]) are passed as float64 arrays of length q.
The integrand peaks like gap / (gap^2 + ...)^(3/2) where the segments nearly touch, which no
fixed rule resolves: its error grows without bound as the gap shrinks.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

Q_INV_4PI = wp.float64(0.07957747154594767)  # 1 / (4 pi)


@wp.func
def gauss_linking_quadrature(
    p1: wp.vec3d,
    p2: wp.vec3d,
    p3: wp.vec3d,
    p4: wp.vec3d,
    nodes: wp.array(dtype=wp.float64),
    weights: wp.array(dtype=wp.float64),
) -> wp.float64:
    """Signed Gauss integral of p1->p2 and p3->p4 by the tensor rule (nodes, weights) on [0, 1]^2."""
    e1 = p2 - p1
    e2 = p4 - p3
    n = wp.cross(e1, e2)
    q = nodes.shape[0]
    total = wp.float64(0.0)
    for i in range(q):
        r1 = p1 + nodes[i] * e1 - p3
        row = wp.float64(0.0)
        for j in range(q):
            r = r1 - nodes[j] * e2
            d2 = wp.dot(r, r)
            row += weights[j] * wp.dot(n, r) / (d2 * wp.sqrt(d2))
        total += weights[i] * row
    return total * Q_INV_4PI


@wp.kernel
def gauss_linking_quadrature_pairs(
    p1: wp.array(dtype=wp.vec3d),
    p2: wp.array(dtype=wp.vec3d),
    p3: wp.array(dtype=wp.vec3d),
    p4: wp.array(dtype=wp.vec3d),
    nodes: wp.array(dtype=wp.float64),
    weights: wp.array(dtype=wp.float64),
    out: wp.array(dtype=wp.float64),
):
    """Quadrature G of segment pairs (p1[i]->p2[i], p3[i]->p4[i]), one pair per thread."""
    i = wp.tid()
    out[i] = gauss_linking_quadrature(p1[i], p2[i], p3[i], p4[i], nodes, weights)
