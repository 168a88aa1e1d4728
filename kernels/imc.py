"""The IMC contact law (incremental potential contact of DisMech), solved implicitly per contact.

The law (Choi et al., J. Appl. Mech. 88, 051010, 2021; Tong et al., Extreme Mech. Lett. 61,
102010, 2023; docs/physics.md, "The IMC contact law"), for a surface gap g (centreline distance
minus the two radii; the same for a rod vertex and a wall):

* normal: the energy k_c [softplus(-K1 g) / K1]^2 with K1 = 15 / delta, so the force
  F(g) = 2 k_c softplus(-K1 g) sigma(-K1 g) / K1 acts within the distance tolerance delta of
  touching (none at a larger gap), is smooth, and is a linear spring 2 k_c (-g) deep in an
  overlap;
* friction on the centreline: F_t = -mu F_n gamma(|v_t|) v_t / |v_t| with
  gamma = 2 / (1 + exp(-K2 |v_t|)) - 1 = tanh(K2 |v_t| / 2), K2 = 15 / nu, below the slip
  tolerance nu and 1 above it: a tangential load T below mu F_n does not stick, it creeps at
  |v_t| = (2 / K2) artanh(T / (mu F_n)).

Formulation: implicit Euler, as DisMech's (it evaluates both at the end-of-step positions and
velocities). A contact's impulse over the step is P = dt F(x', v') with x' = x + dt v', the gap
linearised in the step, g' = g + dt u_n; inside the Gauss-Seidel sweeps each contact's local
problem (the others held fixed) is solved exactly: the normal impulse from a monotone scalar
equation (Newton from below converges monotonically: the equation is concave), then the
friction impulse from the slip speed (a safeguarded Newton in one unknown). The converged sweep
is implicit Euler with this law, so its fixed point is the law's static equilibrium.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF
from rodwarp.kernels.structs import LawParams

wp.set_module_options({"enable_backward": False})

# the law's parameter vector (LawParams), as rodwarp/sim/law_imc.py packs it
STIFFNESS = wp.constant(0)  # k_c (N/m): energy k_c [softplus(K1 (-gap)) / K1]^2
K1 = wp.constant(1)  # 15 / delta (1/m)
K2 = wp.constant(2)  # 15 / nu (s/m)
REACH = wp.constant(3)  # distance tolerance delta (m): no force at a larger gap
NU = wp.constant(4)  # slip tolerance nu (m/s): full Coulomb friction above it


@wp.func
def softplus(x: wp.float64):
    """log(1 + exp(x)) without overflow."""
    if x > F0:
        return x + wp.log(F1 + wp.exp(-x))
    return wp.log(F1 + wp.exp(x))


@wp.func
def logistic(x: wp.float64):
    """1 / (1 + exp(-x)) without overflow."""
    if x >= F0:
        return F1 / (F1 + wp.exp(-x))
    e = wp.exp(x)
    return e / (F1 + e)


@wp.func
def imc_normal_force(gap: wp.float64, lp: LawParams):
    """F(g) (N) of the IMC penalty at surface gap ``gap`` (m) and its slope dF/dg (N/m, <= 0)."""
    if gap > lp[REACH]:
        return wp.vec2d(F0, F0)
    x = -lp[K1] * gap
    sp = softplus(x)
    s = logistic(x)
    k2 = wp.float64(2.0) * lp[STIFFNESS]
    return wp.vec2d(k2 * sp * s / lp[K1], -k2 * (s * s + sp * s * (F1 - s)))


@wp.func
def imc_normal_impulse(gap: wp.float64, c: wp.float64, wnn: wp.float64, guess: wp.float64, dt: wp.float64,
                       lp: LawParams):
    """The normal impulse p >= 0 (N s) with p = dt F(gap + dt (c + wnn p)): ``c`` the normal
    velocity without this impulse (m/s), ``wnn`` the contact's normal mobility.

    h(p) = p - dt F(gap + dt (c + wnn p)) is increasing and concave (F is decreasing and
    convex), h(0) <= 0: Newton from a point left of the root climbs to it monotonically; from
    the right its first step lands left of it (clamped at 0)."""
    p = wp.max(guess, F0)
    for it in range(60):
        fs = imc_normal_force(gap + dt * (c + wnn * p), lp)
        h = p - dt * fs[0]
        dh = F1 - dt * dt * wnn * fs[1]
        step = h / dh
        p_new = wp.max(F0, p - step)
        if wp.abs(p_new - p) <= wp.float64(1.0e-13) * (p_new + wp.float64(1.0e-300)):
            return p_new
        p = p_new
    return p


@wp.func
def smoothed_gamma(s: wp.float64, lp: LawParams):
    """gamma(s) / s and its derivative in s, for slip speed s (m/s) >= 0: gamma = tanh(K2 s / 2)
    below nu, 1 above (series near 0, where the quotient cancels)."""
    if s > lp[NU]:
        return wp.vec2d(F1 / s, -F1 / (s * s))
    hk = HALF * lp[K2]
    x = hk * s
    if x < wp.float64(1.0e-4):
        return wp.vec2d(hk * (F1 - x * x / wp.float64(3.0)), -hk * hk * wp.float64(2.0) * x / wp.float64(3.0))
    t = wp.tanh(x)
    return wp.vec2d(t / s, hk * (x * (F1 - t * t) - t) / (x * x) * hk)


@wp.func
def smoothed_friction_impulse(c1: wp.float64, c2: wp.float64, w11: wp.float64, w12: wp.float64, w22: wp.float64,
                              limit: wp.float64, guess: wp.float64, lp: LawParams):
    """Tangential impulse (p1, p2) (N s) of the smoothed friction, and the slip speed s (m/s):
    p = -limit gamma(s) u / s with u = c + W_t p the end-of-step slip velocity, |u| = s;
    ``limit`` = mu p_n. With beta = limit gamma(s) / s, u = (I + beta W_t)^-1 c and s solves
    psi(s) = |u(s)| - s = 0 in [0, |c|] (psi(0) > 0 >= psi(|c|)): safeguarded Newton."""
    cn = wp.sqrt(c1 * c1 + c2 * c2)
    if limit <= F0 or cn == F0:
        return wp.vec3d(F0, F0, F0)
    lo = F0
    hi = cn
    s = wp.min(wp.max(guess, F0), cn)
    u1 = c1
    u2 = c2
    beta = F0
    for it in range(80):
        g = smoothed_gamma(s, lp)
        beta = limit * g[0]
        a11 = F1 + beta * w11
        a22 = F1 + beta * w22
        a12 = beta * w12
        idet = F1 / (a11 * a22 - a12 * a12)
        u1 = (a22 * c1 - a12 * c2) * idet
        u2 = (a11 * c2 - a12 * c1) * idet
        un = wp.sqrt(u1 * u1 + u2 * u2)
        psi = un - s
        if psi > F0:
            lo = s
        else:
            hi = s
        if wp.abs(psi) <= wp.float64(1.0e-12) * cn or hi - lo <= wp.float64(1.0e-13) * cn:
            break
        # d|u|/dbeta = u . (-(I + beta W)^-1 W u) / |u|
        wu1 = w11 * u1 + w12 * u2
        wu2 = w12 * u1 + w22 * u2
        d1 = -(a22 * wu1 - a12 * wu2) * idet
        d2 = -(a11 * wu2 - a12 * wu1) * idet
        dpsi = (u1 * d1 + u2 * d2) / wp.max(un, wp.float64(1.0e-300)) * limit * g[1] - F1
        s_new = s - psi / dpsi
        if not (s_new > lo and s_new < hi):
            s_new = HALF * (lo + hi)
        s = s_new
    return wp.vec3d(-beta * u1, -beta * u2, s)


# ----------------------------------------------------------------------------- the law's interface
# (kernels/contact_laws.py)


@wp.func
def settings():
    """Three alternations of the normal and tangential parts, to 1e-10; no idle shortcut (the
    penalty acts before contact)."""
    return 3, wp.float64(1.0e-10), 0


@wp.func
def closed_form(uf: wp.vec3d, n: wp.vec3d, target: wp.float64, Winv: wp.mat33d, mu: wp.float64, lp: LawParams):
    """None: every contact within reach is solved by the alternation."""
    return 0, wp.vec3d(F0, F0, F0), F0


@wp.func
def normal_impulse(gap: wp.float64, target: wp.float64, cn: wp.float64, wnn: wp.float64, pn: wp.float64,
                   dt: wp.float64, lp: LawParams):
    """:func:`imc_normal_impulse` from the current impulse ``pn``."""
    return imc_normal_impulse(gap, cn, wnn, pn, dt, lp)


@wp.func
def friction_impulse(c1: wp.float64, c2: wp.float64, w11: wp.float64, w12: wp.float64, w22: wp.float64,
                     limit: wp.float64, guess: wp.float64, lp: LawParams):
    """:func:`smoothed_friction_impulse`; the guess is the slip speed."""
    return smoothed_friction_impulse(c1, c2, w11, w12, w22, limit, guess, lp)
