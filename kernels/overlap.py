"""Post-stabilisation: the overlaps left at the end of a step, removed from the positions.

After the velocity solve (kernels/friction.py) and the position update, each rod-rod and
rod-wall overlap deeper than the slop is pushed apart along its normal by a Baumgarte fraction
of its excess, through the same mobility the contact's impulses use (a rigid capsule moves
rigidly, an elastic rod at the edge's two vertices). Velocities are untouched, so the
correction never adds kinetic energy (docs/performance.md, "The step follows the motion").

Contacts that share a vertex must not be moved concurrently: on the CPU one launch sweeps
them in order, on a GPU the rod-rod contacts go colour by colour and the wall contacts one
thread per rod.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1
from rodwarp.kernels.friction import contact_side, side_response
from rodwarp.kernels.wall_contacts import vertex_edge
from rodwarp.kernels.structs import ContactFrame, ContactSide, RodContacts, RodModel, StepParams, WallContacts, Walls
from rodwarp.kernels.walls import wall_surface

wp.set_module_options({"enable_backward": False})


@wp.func
def side_point(c: ContactSide, x: wp.array(dtype=wp.vec3d)):
    """The side's centreline point at the positions ``x`` (m)."""
    return x[c.i] * (F1 - c.s) + x[c.i + 1] * c.s


@wp.func
def side_shift(c: ContactSide, D: wp.vec3d, x0: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d),
               x: wp.array(dtype=wp.vec3d)):
    """Move the side's rod by the 'position impulse' D through its mobility (a rigid rod as a
    small rigid motion about its start-of-step centre ``x0``, an elastic one at the edge's two
    vertices); velocities are untouched."""
    dx0, dx1, _turn = side_response(c, D, x0, tangent)  # the spin's share turns a round rod onto itself: no shift
    x[c.i] = x[c.i] + dx0
    x[c.i + 1] = x[c.i + 1] + dx1
    return 0


@wp.func
def project_rod_contact(k: int, model: RodModel, contacts: RodContacts, frames: wp.array(dtype=ContactFrame),
                        params: StepParams, x0: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d),
                        x: wp.array(dtype=wp.vec3d)):
    """Remove the part of contact k's overlap beyond the slop at the end-of-step positions
    (along its normal, with its mobility); returns the overlap it found (m)."""
    f = frames[k]
    n = contacts.normal[k]
    ra = model.radius[model.vertex_rod[f.a.i]]
    rb = model.radius[model.vertex_rod[f.b.i]]
    gap = wp.dot(side_point(f.a, x) - side_point(f.b, x), n) - ra - rb
    excess = -gap - params.slop
    if excess <= F0 or f.k[0] <= F0:
        return wp.max(-gap, F0)
    D = n * (params.beta * excess / f.k[0])
    side_shift(f.a, D, x0, tangent, x)
    side_shift(f.b, -D, x0, tangent, x)
    return -gap


@wp.func
def project_rod_walls(r: int, model: RodModel, x0: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d),
                      walls: Walls, params: StepParams, x: wp.array(dtype=wp.vec3d)):
    """The same for rod r's vertex spheres against the walls in place at the end of the step."""
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    rr = model.radius[r]
    worst = F0
    for i in range(a, b):
        e, se = vertex_edge(model, i)
        for p in range(walls.n):
            if walls.on[p] == 0:
                continue
            dist, n = wall_surface(walls, p, x[i], walls.drive_disp + walls.drive_vel * params.dt)
            gap = dist - rr
            excess = -gap - params.slop
            if excess <= F0:
                continue
            worst = wp.max(worst, -gap)
            c, W = contact_side(model, x0, tangent, e, se, n * (-rr))
            wnn = wp.dot(n, W * n)
            if wnn > F0:
                side_shift(c, n * (params.beta * excess / wnn), x0, tangent, x)
    return worst


@wp.kernel
def project_positions_sequential(sweeps: int, tolerance: wp.float64, model: RodModel, x0: wp.array(dtype=wp.vec3d),
                                 contacts: RodContacts, frames: wp.array(dtype=ContactFrame),
                                 tangent: wp.array(dtype=wp.vec3d), walls: Walls, wall_contacts: WallContacts,
                                 params: StepParams, x: wp.array(dtype=wp.vec3d), out: wp.array(dtype=wp.float64)):
    """Post-stabilisation on a sequential device (dim = 1): at most ``sweeps`` Gauss-Seidel
    passes over the rod-rod contacts and the rods near walls, stopping after a pass that found
    no overlap deeper than ``tolerance`` (m); out[0] = the deepest overlap the last pass found,
    out[1] = the passes run."""
    worst = F0
    used = int(0)
    na = wall_contacts.n_active[0]
    for it in range(sweeps):
        worst = F0
        for k in range(contacts.count):
            worst = wp.max(worst, project_rod_contact(k, model, contacts, frames, params, x0, tangent, x))
        for q in range(na):
            worst = wp.max(worst, project_rod_walls(wall_contacts.active[q], model, x0, tangent, walls, params, x))
        used = it + 1
        if worst <= tolerance:
            break
    out[0] = worst
    out[1] = wp.float64(used)


@wp.kernel
def project_rod_contacts(ids: wp.array(dtype=wp.int32), use_ids: int, model: RodModel, contacts: RodContacts,
                         frames: wp.array(dtype=ContactFrame), params: StepParams, x0: wp.array(dtype=wp.vec3d),
                         tangent: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.vec3d)):
    """One thread per contact of one colour (GPU)."""
    k = wp.tid()
    if use_ids != 0:
        k = ids[k]
    project_rod_contact(k, model, contacts, frames, params, x0, tangent, x)


@wp.kernel
def project_wall_contacts(model: RodModel, x0: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d),
                          walls: Walls, wall_contacts: WallContacts, params: StepParams, x: wp.array(dtype=wp.vec3d)):
    """One thread per rod near a wall (GPU)."""
    project_rod_walls(wall_contacts.active[wp.tid()], model, x0, tangent, walls, params, x)
