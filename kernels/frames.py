"""Material frames of the edges: reference directors, twist and the rest curvature they carry.

Each edge j carries a reference director u_j (unit, normal to the edge) that is moved with
the edge by *time-parallel transport* (the smallest rotation that takes the old tangent to
the new one, so u never spins about the tangent), and a material angle theta_j measured
from u_j about the tangent; the material frame is

    m1_j = cos(theta_j) u_j + sin(theta_j) (t_j x u_j),     m2_j = t_j x m1_j.

Because u does not spin, d(theta_j)/dt is exactly the angular velocity of the material about
its axis (the ``spin``), which friction at the rod's surface drives (discrete elastic rods,
Bergou et al. 2008, 2010). The twist at an interior vertex is theta_i - theta_{i-1} plus
the *reference twist*, the angle between u_i and u_{i-1} carried over to edge i by
space-parallel transport.

A curved rod's rest curvature is stored as its two components (k1, k2) in the vertex
material frame, so the curvature it wants to keep turns with the material: a curved rod that
rolls carries its shape around its axis (twist-bend coupling).
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF
from rodwarp.kernels.structs import RodFactors, RodModel, RodState

wp.set_module_options({"enable_backward": False})


@wp.func
def parallel_transport(u: wp.vec3d, t0: wp.vec3d, t1: wp.vec3d):
    """u rotated by the smallest rotation taking unit t0 to unit t1 (Rodrigues)."""
    b = wp.cross(t0, t1)
    c = wp.dot(t0, t1)
    if c <= wp.float64(-1.0) + wp.float64(1.0e-12):
        return u  # opposite tangents: no unique transport (cannot happen within one step)
    return u * c + wp.cross(b, u) + b * (wp.dot(b, u) / (F1 + c))


@wp.func
def unit_normal_to(u: wp.vec3d, t: wp.vec3d):
    """u with its component along unit t removed, normalised (re-orthonormalisation)."""
    w = u - t * wp.dot(u, t)
    return w / wp.length(w)


@wp.func
def signed_angle(a: wp.vec3d, b: wp.vec3d, axis: wp.vec3d):
    """Angle from a to b about ``axis`` (rad, in (-pi, pi])."""
    return wp.atan2(wp.dot(wp.cross(a, b), axis), wp.dot(a, b))


@wp.func
def edge_tangent(x: wp.array(dtype=wp.vec3d), j: int):
    e = x[j + 1] - x[j]
    return e / wp.length(e)


@wp.func
def material_d1(u: wp.vec3d, t: wp.vec3d, theta: wp.float64):
    return u * wp.cos(theta) + wp.cross(t, u) * wp.sin(theta)


@wp.func
def vertex_frame_d1(d1m: wp.vec3d, tm: wp.vec3d, d1p: wp.vec3d, tp: wp.vec3d, b: wp.vec3d):
    """First director of the vertex frame: the two edge directors carried to the bisector b, averaged."""
    return unit_normal_to(parallel_transport(d1m, tm, b) + parallel_transport(d1p, tp, b), b)


@wp.func
def rest_target(k: wp.vec2d, d1m: wp.vec3d, tm: wp.vec3d, d1p: wp.vec3d, tp: wp.vec3d):
    """Rest curvature vector of an interior vertex in the current material frame, and its bisector."""
    b = wp.normalize(tm + tp)
    m1 = vertex_frame_d1(d1m, tm, d1p, tp, b)
    m2 = wp.cross(b, m1)
    return m1 * k[0] + m2 * k[1], b


@wp.kernel
def step_frames(model: RodModel, state: RodState, factors: RodFactors):
    """One thread per rod, at the start of a step: edge tangents, reference twists and, for
    curved rods, the rest curvature targets T_i and their sensitivity dT_i/dtheta = b x T_i / 2
    to each adjacent edge's material angle."""
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    for j in range(a, b - 1):
        factors.tangent[j] = edge_tangent(state.x, j)
    for i in range(a + 1, b - 1):
        tm = factors.tangent[i - 1]
        tp = factors.tangent[i]
        factors.ref_twist[i] = signed_angle(parallel_transport(state.director[i - 1], tm, tp), state.director[i], tp)
        if model.curved[r] != 0:
            d1m = material_d1(state.director[i - 1], tm, state.theta[i - 1])
            d1p = material_d1(state.director[i], tp, state.theta[i])
            T, bis = rest_target(model.rest_kappa[i], d1m, tm, d1p, tp)
            factors.bend_target[i] = T
            factors.curved_coupling[i] = wp.cross(bis, T) * HALF
        else:
            factors.bend_target[i] = wp.vec3d(F0, F0, F0)
            factors.curved_coupling[i] = wp.vec3d(F0, F0, F0)


@wp.kernel
def advance_frames(model: RodModel, x_old: wp.array(dtype=wp.vec3d), x_new: wp.array(dtype=wp.vec3d),
                   director_in: wp.array(dtype=wp.vec3d), theta_in: wp.array(dtype=wp.float64),
                   spin: wp.array(dtype=wp.float64), dt: wp.float64, director_out: wp.array(dtype=wp.vec3d),
                   theta_out: wp.array(dtype=wp.float64)):
    """Per vertex slot (edges only): transport the director with its edge, theta += dt spin."""
    j = wp.tid()
    r = model.vertex_rod[j]
    if j >= model.rod_start[r + 1] - 1:
        director_out[j] = director_in[j]
        theta_out[j] = theta_in[j]
        return
    t0 = edge_tangent(x_old, j)
    t1 = edge_tangent(x_new, j)
    director_out[j] = unit_normal_to(parallel_transport(director_in[j], t0, t1), t1)
    theta_out[j] = theta_in[j] + dt * spin[j]
