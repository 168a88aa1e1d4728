"""The exact contact law: Signorini non-penetration and the Coulomb cone, sticking exactly.

Device functions of the law (the interface: :mod:`rodwarp.kernels.contact_laws`; host side
:mod:`rodwarp.sim.law_exact`; docs/physics.md, "Contact"). The normal impulse keeps the normal
velocity above its target with P_n >= 0; the tangential impulse satisfies |P_t| <= mu P_n
exactly: it sticks when -W_t^-1 u_t lies inside the disc, else it slides on the cone's edge
with maximal dissipation, P_t = -(W_t + gamma I)^-1 u_t, gamma from Newton's method on
1 / |P_t(gamma)| (concave, so the iteration converges monotonically; one step when W_t is
isotropic). No pyramid, true sticking. The law has no parameters (``lp`` unused).
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF
from rodwarp.kernels.structs import LawParams

wp.set_module_options({"enable_backward": False})


@wp.func
def settings():
    """Two alternations of the normal and tangential parts, to 1e-9; idle contacts skipped."""
    return 2, wp.float64(1.0e-9), 1


@wp.func
def closed_form(uf: wp.vec3d, n: wp.vec3d, target: wp.float64, Winv: wp.mat33d, mu: wp.float64, lp: LawParams):
    """Two cases in closed form: a contact that does not approach faster than its target
    without an impulse gets none, and one whose sticking impulse W^-1 (target n - u_f) lies
    inside the friction cone sticks with exactly that impulse (with W coupling the parts, the
    alternation would only approach it). The rest slide on the cone's edge."""
    if wp.dot(uf, n) >= target:
        return 1, wp.vec3d(F0, F0, F0), F0  # separating or resting without load: no impulse
    Ps = Winv * (n * target - uf)
    psn = wp.dot(Ps, n)
    if psn > F0:
        pst = Ps - n * psn
        if wp.dot(pst, pst) <= mu * mu * psn * psn:
            return 1, Ps, F0  # sticks: the exact impulse
    return 0, wp.vec3d(F0, F0, F0), F0


@wp.func
def normal_impulse(gap: wp.float64, target: wp.float64, cn: wp.float64, wnn: wp.float64, pn: wp.float64,
                   dt: wp.float64, lp: LawParams):
    """Signorini: the least P_n >= 0 that brings the normal velocity to its target."""
    return wp.max(F0, (target - cn) / wnn)


@wp.func
def friction_impulse(c1: wp.float64, c2: wp.float64, w11: wp.float64, w12: wp.float64, w22: wp.float64,
                     limit: wp.float64, guess: wp.float64, lp: LawParams):
    """The Coulomb cone (:func:`coulomb_2d`); the guess is the sliding multiplier gamma."""
    return coulomb_2d(c1, c2, w11, w12, w22, limit, guess)


@wp.func
def coulomb_2d(u1: wp.float64, u2: wp.float64, w11: wp.float64, w12: wp.float64, w22: wp.float64,
               limit: wp.float64, gamma0: wp.float64):
    """Tangential impulse (p1, p2) with u + W p = 0 when |p| <= limit (sticking), else on the
    disc's edge with u + W p anti-parallel to p (sliding with maximal dissipation), and the
    sliding multiplier gamma (0 when it sticks). ``gamma0``: a guess of gamma (the same
    contact's in the last sweep), where Newton starts when it is above the lower bound."""
    if limit <= F0:
        return wp.vec3d(F0, F0, F0)
    # each 2 x 2 solve takes one reciprocal of its determinant, not a division per entry: a
    # sliding contact runs this Newton loop in every sweep, and divisions set its latency
    idet = F1 / (w11 * w22 - w12 * w12)
    y1 = (w22 * u1 - w12 * u2) * idet
    y2 = (w11 * u2 - w12 * u1) * idet
    ny2 = y1 * y1 + y2 * y2
    if ny2 <= limit * limit:
        return wp.vec3d(-y1, -y2, F0)  # sticks: the exact impulse
    inv_limit = F1 / limit
    # a lower bound of the root, |u| / limit - lambda_max(W): phi below is concave, so Newton
    # climbs from there to the root without overshooting; from a guess above the root its
    # first step lands below it (kept above the bound), then it climbs
    half_tr = HALF * (w11 + w22)
    hd = HALF * (w11 - w22)
    lower = wp.max(F0, wp.sqrt(u1 * u1 + u2 * u2) * inv_limit - half_tr - wp.sqrt(hd * hd + w12 * w12))
    gamma = wp.max(lower, gamma0)
    m11 = w11 + gamma
    m22 = w22 + gamma
    if gamma > F0:
        idet = F1 / (m11 * m22 - w12 * w12)
        y1 = (m22 * u1 - w12 * u2) * idet
        y2 = (m11 * u2 - w12 * u1) * idet
        ny2 = y1 * y1 + y2 * y2
    ny = wp.sqrt(ny2)
    for it in range(40):
        if wp.abs(ny * inv_limit - F1) <= wp.float64(1.0e-10):
            break
        # Newton on phi(gamma) = 1 / |y| - 1 / limit; phi' = y^T (W + gamma I)^-1 y / |y|^3
        z1 = (m22 * y1 - w12 * y2) * idet
        z2 = (m11 * y2 - w12 * y1) * idet
        gamma = wp.max(lower, gamma + (ny * inv_limit - F1) * ny2 / (y1 * z1 + y2 * z2))
        m11 = w11 + gamma
        m22 = w22 + gamma
        idet = F1 / (m11 * m22 - w12 * w12)
        y1 = (m22 * u1 - w12 * u2) * idet
        y2 = (m11 * u2 - w12 * u1) * idet
        ny2 = y1 * y1 + y2 * y2
        ny = wp.sqrt(ny2)
    sc = limit / ny
    return wp.vec3d(-y1 * sc, -y2 * sc, gamma)
