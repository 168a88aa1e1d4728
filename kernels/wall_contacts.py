"""Rod-wall contacts: their gaps and frames once per step, their exact local solves in the sweeps.

A rod touches a wall at its vertex spheres (kernels/walls.py says why that suffices for every
kind); each in-reach vertex x wall pair is a contact with the same local problem as a rod-rod
contact (kernels/friction.py), side ``a`` the rod's, the wall immobile and moving with its
drive. One thread per rod that touches a wall, so a rod's wall contacts never race.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, FAR
from rodwarp.kernels.friction import (approach_target, contact_side, local_frame, relaxed, restitution_target,
                                      side_apply, side_apply_atomic, side_velocity, solve_contact)
from rodwarp.kernels.structs import ContactFrame, RodModel, StepParams, WallContacts, Walls
from rodwarp.kernels.walls import wall_surface, wall_velocity

wp.set_module_options({"enable_backward": False})


@wp.func
def wall_contact_exact(f: ContactFrame, P: wp.vec3d, n: wp.vec3d, walls: Walls, p: int, params: StepParams,
                       v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64)):
    """``rod_contact_exact`` for a contact with wall p of normal ``n`` (frame side ``a`` the rod's)."""
    return solve_contact(side_velocity(f.a, v, spin) - wall_velocity(walls, p), f, n, P, walls.mu[p], params)


@wp.func
def vertex_edge(model: RodModel, i: int):
    """The edge a wall contact at vertex i belongs to, and its parameter there (a rod's last
    vertex: the end of its last edge)."""
    r = model.vertex_rod[i]
    if i >= model.rod_start[r + 1] - 1:
        return i - 1, F1
    return i, F0


@wp.func
def wall_frame(model: RodModel, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d), walls: Walls,
               params: StepParams, contacts: WallContacts, k: int, v0: wp.array(dtype=wp.vec3d),
               spin0: wp.array(dtype=wp.float64)):
    """The local frame of wall contact k (vertex x wall), side ``a`` the rod's; ``v0``,
    ``spin0`` as in ``prepare_rod_contacts`` (restitution only)."""
    i = k // walls.n
    e, se = vertex_edge(model, i)
    n = contacts.normal[k]
    c, W = contact_side(model, x, tangent, e, se, n * (-model.radius[model.vertex_rod[i]]))
    target = approach_target(contacts.gap[k], params)
    if params.restitution > F0:
        vn = wp.dot(side_velocity(c, v0, spin0) - wall_velocity(walls, k % walls.n), n)
        target = restitution_target(target, contacts.gap[k], vn, params)
    f = local_frame(W, n, target)
    f.gap = contacts.gap[k]
    f.a = c
    return f


@wp.func
def write_wall_frames(model: RodModel, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d), walls: Walls,
                      params: StepParams, contacts: WallContacts, r: int, base: int, v0: wp.array(dtype=wp.vec3d),
                      spin0: wp.array(dtype=wp.float64)):
    """The frames and keys of rod r's wall contacts in reach, written from slot ``base`` on."""
    j = base
    for k in range(model.rod_start[r] * walls.n, model.rod_start[r + 1] * walls.n):
        if contacts.gap[k] < FAR:
            contacts.key[j] = k
            contacts.frames[j] = wall_frame(model, x, tangent, walls, params, contacts, k, v0, spin0)
            j += 1


@wp.kernel
def prepare_wall_contacts(model: RodModel, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d), walls: Walls,
                          params: StepParams, contacts: WallContacts, v: wp.array(dtype=wp.vec3d),
                          spin: wp.array(dtype=wp.float64), v0: wp.array(dtype=wp.vec3d),
                          spin0: wp.array(dtype=wp.float64)):
    """One thread per rod: gaps of its vertex spheres to every wall at the start of the step,
    warm-started impulses (applied); a rod with any contact within reach joins ``active``
    with a span of frames (written when they fit; the host grows the list otherwise).

    A capsule touches a plane first at a segment endpoint, so vertex spheres suffice.
    Contacts out of reach get gap = +inf and zero impulse. ``v0``, ``spin0``: the velocities
    before this step's contact impulses, rigid rods as bodies (restitution only).
    """
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    rr = model.radius[r]
    count = int(0)
    for i in range(a, b):
        e, se = vertex_edge(model, i)
        for p in range(walls.n):
            k = i * walls.n + p
            dist, n = wall_surface(walls, p, x[i], walls.drive_disp)
            g = dist - rr
            closing = wp.max(-wp.dot(v[i] - wall_velocity(walls, p), n), F0)
            if walls.on[p] != 0 and g < params.contact_distance + closing * params.dt * wp.float64(2.0):
                contacts.gap[k] = g
                contacts.normal[k] = n
                P = contacts.impulse[k] * params.warm
                pn = wp.max(wp.dot(P, n), F0)
                P = n * pn + (P - n * wp.dot(P, n))
                contacts.impulse[k] = P
                c, W = contact_side(model, x, tangent, e, se, n * (-rr))
                side_apply_atomic(c, P, x, tangent, v, spin)
                count += 1
            else:
                contacts.gap[k] = FAR
                contacts.impulse[k] = wp.vec3d(F0, F0, F0)
    if count == 0:
        return
    base = wp.atomic_add(contacts.n_frames, 0, count)
    q = wp.atomic_add(contacts.n_active, 0, 1)
    contacts.active[q] = r
    contacts.span[q] = wp.vec2i(base, count)
    if base + count > contacts.frames.shape[0]:
        return
    write_wall_frames(model, x, tangent, walls, params, contacts, r, base, v0, spin0)


@wp.kernel
def fill_wall_frames(model: RodModel, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d), walls: Walls,
                     params: StepParams, contacts: WallContacts, v0: wp.array(dtype=wp.vec3d),
                     spin0: wp.array(dtype=wp.float64)):
    """One thread per active rod: its span of frames (after the host grew the list)."""
    q = wp.tid()
    write_wall_frames(model, x, tangent, walls, params, contacts, contacts.active[q], contacts.span[q][0], v0, spin0)


@wp.func
def solve_rod_walls(q: int, walls: Walls, params: StepParams, contacts: WallContacts, v: wp.array(dtype=wp.vec3d),
                    spin: wp.array(dtype=wp.float64)):
    """Every wall contact of active rod q in turn (same exact local solve as rod-rod
    contacts, frames prepared once per step); returns the square of the largest velocity
    change caused (m^2/s^2)."""
    worst = F0
    sp = contacts.span[q]
    for j in range(sp[0], sp[0] + sp[1]):
        k = contacts.key[j]
        p = k % walls.n
        f = contacts.frames[j]
        P = contacts.impulse[k]
        n = contacts.normal[k]
        P_exact, gamma = wall_contact_exact(f, P, n, walls, p, params, v, spin)
        contacts.frames[j].gamma = gamma
        P_new = relaxed(P_exact, P, n, walls.mu[p], params.relax)
        dP = P_new - P
        side_apply(f.a, dP, v, spin)
        contacts.impulse[k] = P_new
        du = f.W * dP
        worst = wp.max(worst, wp.dot(du, du))
    return worst


@wp.kernel
def solve_wall_contacts(walls: Walls, params: StepParams, contacts: WallContacts, v: wp.array(dtype=wp.vec3d),
                        spin: wp.array(dtype=wp.float64), residual: wp.array(dtype=wp.float64)):
    """One thread per rod that touches a wall (``active`` lists them); the residual squared."""
    wp.atomic_max(residual, 0, solve_rod_walls(wp.tid(), walls, params, contacts, v, spin))


@wp.kernel
def wall_contact_residual(walls: Walls, params: StepParams, contacts: WallContacts, v: wp.array(dtype=wp.vec3d),
                          spin: wp.array(dtype=wp.float64), residual: wp.array(dtype=wp.float64)):
    """``rod_contact_residual`` for the wall contacts (one thread per frame)."""
    j = wp.tid()
    if j >= contacts.n_frames[0]:
        return
    k = contacts.key[j]
    f = contacts.frames[j]
    P = contacts.impulse[k]
    P_exact, gamma = wall_contact_exact(f, P, contacts.normal[k], walls, k % walls.n, params, v, spin)
    wp.atomic_max(residual, 0, wp.length(f.W * (P_exact - P)))
