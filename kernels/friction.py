"""Contact and Coulomb friction at the rods' surfaces, by projected Gauss-Seidel on velocities.

Each contact holds an accumulated impulse P (N s) acting at the two surface points
(x_a - r_a n on rod a, x_b + r_b n on rod b; n points from b to a). The relative velocity
of the surface points includes each edge's spin omega about its tangent t:

    u = v_a(s) - v_b(t) - r_a omega_a (t_a x n) - r_b omega_b (t_b x n),

and a tangential impulse applies an axial torque, so friction rolls and spins rods. The
local effective mass is

    W = w I + (r_a^2 / I_a) g_a g_a^T + (r_b^2 / I_b) g_b g_b^T,     g = t x n,

with w the centreline term (isotropic, from the tridiagonal inverse mass). Because every
g is normal to n, the normal and tangential parts decouple: the normal impulse is solved in
closed form, and the tangential one exactly on the Coulomb cone |P_t| <= mu P_n with the
anisotropic 2 x 2 W_t: sticking when -W_t^-1 u_t lies inside the disc, else the sliding
impulse P_t = -(W_t + gamma I)^-1 u_t with |P_t| = mu P_n (maximal dissipation), gamma found
by Newton on 1 / |P_t(gamma)| (concave, so the iteration converges monotonically; one step
when W_t is isotropic). No pyramid, true sticking.

Contacts that share a vertex (hence an edge) must not be visited concurrently. On the CPU a
launch runs its threads in order (sequential Gauss-Seidel); on a GPU rod-rod contacts are
coloured first (``color_claim`` / ``color_commit``) and each colour is one launch, and wall
contacts run one thread per rod.
"""

import warp as wp

from rodwarp.kernels.narrowphase import any_perpendicular
from rodwarp.kernels.structs import RodContacts, RodFactors, RodModel, StepParams, WallContacts, Walls

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)
F1 = wp.float64(1.0)
FAR = wp.float64(1.0e299)


@wp.func
def approach_target(gap: wp.float64, dt: wp.float64, beta: wp.float64, max_push: wp.float64):
    """Lowest normal relative velocity allowed this step (m/s)."""
    if gap >= F0:
        return -gap / dt
    return wp.min(-beta * gap / dt, max_push)


@wp.func
def coulomb_tangential(u: wp.vec3d, n: wp.vec3d, w: wp.float64, ka: wp.float64, ga: wp.vec3d, kb: wp.float64,
                       gb: wp.vec3d, limit: wp.float64):
    """Tangential impulse that leaves u + W P_t sticking, or sliding on the cone edge.

    ``u`` is the tangential velocity without this contact's tangential impulse, W = w I +
    ka ga ga^T + kb gb gb^T (restricted to the plane normal to n), ``limit`` = mu P_n.
    """
    if limit <= F0:
        return wp.vec3d(F0, F0, F0)
    e1 = any_perpendicular(n)
    e2 = wp.cross(n, e1)
    u1 = wp.dot(u, e1)
    u2 = wp.dot(u, e2)
    a1 = wp.dot(ga, e1)
    a2 = wp.dot(ga, e2)
    b1 = wp.dot(gb, e1)
    b2 = wp.dot(gb, e2)
    w11 = w + ka * a1 * a1 + kb * b1 * b1
    w12 = ka * a1 * a2 + kb * b1 * b2
    w22 = w + ka * a2 * a2 + kb * b2 * b2
    det0 = w11 * w22 - w12 * w12
    y1 = (w22 * u1 - w12 * u2) / det0
    y2 = (w11 * u2 - w12 * u1) / det0
    ny = wp.sqrt(y1 * y1 + y2 * y2)
    if ny <= limit:
        return -(e1 * y1 + e2 * y2)  # sticks: the exact impulse
    gamma = F0
    for it in range(40):
        if ny <= limit * (F1 + wp.float64(1.0e-10)):
            break
        m11 = w11 + gamma
        m22 = w22 + gamma
        det = m11 * m22 - w12 * w12
        # Newton on phi(gamma) = 1 / |y| - 1 / limit; phi' = y^T (W + gamma I)^-1 y / |y|^3
        z1 = (m22 * y1 - w12 * y2) / det
        z2 = (m11 * y2 - w12 * y1) / det
        gamma = gamma + (ny / limit - F1) * ny * ny / (y1 * z1 + y2 * z2)
        m11 = w11 + gamma
        m22 = w22 + gamma
        det = m11 * m22 - w12 * w12
        y1 = (m22 * u1 - w12 * u2) / det
        y2 = (m11 * u2 - w12 * u1) / det
        ny = wp.sqrt(y1 * y1 + y2 * y2)
    return -(e1 * y1 + e2 * y2) * (limit / ny)


@wp.func
def point_weights(w0: wp.float64, w1: wp.float64, c: wp.float64, s: wp.float64):
    """Rows of the tridiagonal M^-1 at a point (1 - s, s) of an edge: the velocity change of
    each end per unit impulse, and the point's own inverse mass."""
    q0 = (F1 - s) * w0 + s * c
    q1 = (F1 - s) * c + s * w1
    return q0, q1, (F1 - s) * q0 + s * q1


@wp.func
def solve_rod_contact(
    k: int,
    model: RodModel,
    contacts: RodContacts,
    tangent: wp.array(dtype=wp.vec3d),
    params: StepParams,
    v: wp.array(dtype=wp.vec3d),
    spin: wp.array(dtype=wp.float64),
):
    """Exact local solve of rod-rod contact k; returns the velocity change it caused (m/s)."""
    sp = contacts.seg[k]
    ia = model.seg_vertex[sp[0]]
    ib = model.seg_vertex[sp[1]]
    s = contacts.st[k][0]
    t = contacts.st[k][1]
    qa0, qa1, wa = point_weights(model.inv_mass[ia], model.inv_mass[ia + 1], model.cross_inv_mass[ia], s)
    qb0, qb1, wb = point_weights(model.inv_mass[ib], model.inv_mass[ib + 1], model.cross_inv_mass[ib], t)
    w = wa + wb
    if w <= F0:
        return F0
    n = contacts.normal[k]
    ra = model.radius[model.vertex_rod[ia]]
    rb = model.radius[model.vertex_rod[ib]]
    ga = wp.cross(tangent[ia], n)
    gb = wp.cross(tangent[ib], n)
    ka = ra * ra * model.inv_inertia[ia]
    kb = rb * rb * model.inv_inertia[ib]
    u = (v[ia] * (F1 - s) + v[ia + 1] * s) - (v[ib] * (F1 - t) + v[ib + 1] * t) - ga * (ra * spin[ia]) - \
        gb * (rb * spin[ib])
    P = contacts.impulse[k]
    pn = wp.dot(P, n)
    pt = P - n * pn
    un = wp.dot(u, n)
    pn_new = wp.max(F0, pn + (approach_target(contacts.gap[k], params.dt, params.beta, params.max_push) - un) / w)
    # tangential velocity without this contact's tangential impulse
    ut = u - n * un - (pt * w + ga * (ka * wp.dot(ga, pt)) + gb * (kb * wp.dot(gb, pt)))
    pt_new = coulomb_tangential(ut, n, w, ka, ga, kb, gb, params.mu * pn_new)
    dP = n * (pn_new - pn) + (pt_new - pt)
    v[ia] = v[ia] + dP * qa0
    v[ia + 1] = v[ia + 1] + dP * qa1
    v[ib] = v[ib] - dP * qb0
    v[ib + 1] = v[ib + 1] - dP * qb1
    spin[ia] = spin[ia] - wp.dot(dP, ga) * (ra * model.inv_inertia[ia])
    spin[ib] = spin[ib] - wp.dot(dP, gb) * (rb * model.inv_inertia[ib])
    contacts.impulse[k] = n * pn_new + pt_new
    du = dP * w + ga * (ka * wp.dot(ga, dP)) + gb * (kb * wp.dot(gb, dP))
    return wp.length(du)


@wp.kernel
def solve_rod_contacts(
    ids: wp.array(dtype=wp.int32),
    use_ids: int,
    model: RodModel,
    contacts: RodContacts,
    tangent: wp.array(dtype=wp.vec3d),
    params: StepParams,
    v: wp.array(dtype=wp.vec3d),
    spin: wp.array(dtype=wp.float64),
    residual: wp.array(dtype=wp.float64),
):
    """One thread per contact of one colour (GPU) or of all contacts in order (CPU)."""
    k = wp.tid()
    if use_ids != 0:
        k = ids[k]
    wp.atomic_max(residual, 0, solve_rod_contact(k, model, contacts, tangent, params, v, spin))


@wp.kernel
def apply_rod_impulses(
    model: RodModel,
    contacts: RodContacts,
    tangent: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    spin: wp.array(dtype=wp.float64),
):
    """Warm start: apply the reused impulses once before iterating (atomics: any order)."""
    k = wp.tid()
    if k >= contacts.count:
        return
    sp = contacts.seg[k]
    ia = model.seg_vertex[sp[0]]
    ib = model.seg_vertex[sp[1]]
    s = contacts.st[k][0]
    t = contacts.st[k][1]
    qa0, qa1, wa = point_weights(model.inv_mass[ia], model.inv_mass[ia + 1], model.cross_inv_mass[ia], s)
    qb0, qb1, wb = point_weights(model.inv_mass[ib], model.inv_mass[ib + 1], model.cross_inv_mass[ib], t)
    P = contacts.impulse[k]
    n = contacts.normal[k]
    wp.atomic_add(v, ia, P * qa0)
    wp.atomic_add(v, ia + 1, P * qa1)
    wp.atomic_sub(v, ib, P * qb0)
    wp.atomic_sub(v, ib + 1, P * qb1)
    ra = model.radius[model.vertex_rod[ia]]
    rb = model.radius[model.vertex_rod[ib]]
    wp.atomic_sub(spin, ia, wp.dot(P, wp.cross(tangent[ia], n)) * (ra * model.inv_inertia[ia]))
    wp.atomic_sub(spin, ib, wp.dot(P, wp.cross(tangent[ib], n)) * (rb * model.inv_inertia[ib]))


# ----------------------------------------------------------------------------- walls


@wp.func
def vertex_edge(model: RodModel, i: int):
    """The edge whose spin a wall contact at vertex i acts on (a rod's last vertex: its last edge)."""
    r = model.vertex_rod[i]
    if i >= model.rod_start[r + 1] - 1:
        return i - 1
    return i


@wp.func
def apply_vertex_impulse(model: RodModel, i: int, e: int, P: wp.vec3d, g: wp.vec3d, rr: wp.float64,
                         v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64)):
    """Impulse P at vertex i's surface point: M^-1 column i (with the rigid rods' cross terms)
    and the axial torque on edge e (g = t_e x n, rr = the rod radius)."""
    r = model.vertex_rod[i]
    v[i] = v[i] + P * model.inv_mass[i]
    if i + 1 < model.rod_start[r + 1]:
        v[i + 1] = v[i + 1] + P * model.cross_inv_mass[i]
    if i > model.rod_start[r]:
        v[i - 1] = v[i - 1] + P * model.cross_inv_mass[i - 1]
    spin[e] = spin[e] - wp.dot(P, g) * (rr * model.inv_inertia[e])
    return 0


@wp.kernel
def prepare_wall_contacts(
    model: RodModel,
    x: wp.array(dtype=wp.vec3d),
    tangent: wp.array(dtype=wp.vec3d),
    walls: Walls,
    params: StepParams,
    contacts: WallContacts,
    v: wp.array(dtype=wp.vec3d),
    spin: wp.array(dtype=wp.float64),
):
    """One thread per rod: gaps of its vertex spheres to every wall at the start of the step,
    warm-started impulses (applied), and the rod joins ``active`` when any is within reach.

    A capsule touches a plane first at a segment endpoint, so vertex spheres suffice.
    Contacts out of reach get gap = +inf and zero impulse.
    """
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    rr = model.radius[r]
    any_active = int(0)
    for i in range(a, b):
        e = vertex_edge(model, i)
        for p in range(walls.n):
            k = i * walls.n + p
            n = walls.normal[p]
            g = wp.dot(n, x[i]) - walls.offset[p] - rr
            closing = wp.max(-wp.dot(v[i] - walls.vel[p], n), F0)
            if walls.on[p] != 0 and g < params.contact_distance + closing * params.dt * wp.float64(2.0):
                contacts.gap[k] = g
                P = contacts.impulse[k] * params.warm
                pn = wp.max(wp.dot(P, n), F0)
                P = n * pn + (P - n * wp.dot(P, n))
                contacts.impulse[k] = P
                apply_vertex_impulse(model, i, e, P, wp.cross(tangent[e], n), rr, v, spin)
                any_active = 1
            else:
                contacts.gap[k] = FAR
                contacts.impulse[k] = wp.vec3d(F0, F0, F0)
    if any_active != 0:
        contacts.active[wp.atomic_add(contacts.n_active, 0, 1)] = r


@wp.func
def solve_rod_walls(
    r: int,
    model: RodModel,
    tangent: wp.array(dtype=wp.vec3d),
    walls: Walls,
    params: StepParams,
    contacts: WallContacts,
    v: wp.array(dtype=wp.vec3d),
    spin: wp.array(dtype=wp.float64),
):
    """Every wall contact of rod r in turn (same exact local solve as rod-rod contacts);
    returns the largest velocity change caused (m/s)."""
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    rr = model.radius[r]
    worst = F0
    for i in range(a, b):
        w = model.inv_mass[i]
        e = vertex_edge(model, i)
        kr = rr * rr * model.inv_inertia[e]
        for p in range(walls.n):
            k = i * walls.n + p
            gap = contacts.gap[k]
            if gap > FAR or w <= F0:
                continue
            n = walls.normal[p]
            g = wp.cross(tangent[e], n)
            u = v[i] - g * (rr * spin[e]) - walls.vel[p]
            P = contacts.impulse[k]
            pn = wp.dot(P, n)
            pt = P - n * pn
            un = wp.dot(u, n)
            pn_new = wp.max(F0, pn + (approach_target(gap, params.dt, params.beta, params.max_push) - un) / w)
            ut = u - n * un - (pt * w + g * (kr * wp.dot(g, pt)))
            pt_new = coulomb_tangential(ut, n, w, kr, g, F0, g, walls.mu[p] * pn_new)
            dP = n * (pn_new - pn) + (pt_new - pt)
            apply_vertex_impulse(model, i, e, dP, g, rr, v, spin)
            contacts.impulse[k] = n * pn_new + pt_new
            worst = wp.max(worst, wp.length(dP * w + g * (kr * wp.dot(g, dP))))
    return worst


@wp.kernel
def solve_wall_contacts(
    model: RodModel,
    tangent: wp.array(dtype=wp.vec3d),
    walls: Walls,
    params: StepParams,
    contacts: WallContacts,
    v: wp.array(dtype=wp.vec3d),
    spin: wp.array(dtype=wp.float64),
    residual: wp.array(dtype=wp.float64),
):
    """One thread per rod that touches a wall (``active`` lists them)."""
    r = contacts.active[wp.tid()]
    wp.atomic_max(residual, 0, solve_rod_walls(r, model, tangent, walls, params, contacts, v, spin))


# ----------------------------------------------------------------------------- colouring


@wp.kernel
def color_claim(
    count: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    color: wp.array(dtype=wp.int32),
    owner: wp.array(dtype=wp.int32),
):
    """Each uncoloured contact bids for its four vertices; the lowest index wins each."""
    k = wp.tid()
    if k >= count or color[k] >= 0:
        return
    ia = seg_vertex[seg[k][0]]
    ib = seg_vertex[seg[k][1]]
    wp.atomic_min(owner, ia, k)
    wp.atomic_min(owner, ia + 1, k)
    wp.atomic_min(owner, ib, k)
    wp.atomic_min(owner, ib + 1, k)


@wp.kernel
def color_commit(
    count: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    round_id: int,
    owner: wp.array(dtype=wp.int32),
    color: wp.array(dtype=wp.int32),
    remaining: wp.array(dtype=wp.int32),
):
    """A contact that won all its vertices takes this round's colour (an independent set)."""
    k = wp.tid()
    if k >= count or color[k] >= 0:
        return
    ia = seg_vertex[seg[k][0]]
    ib = seg_vertex[seg[k][1]]
    if owner[ia] == k and owner[ia + 1] == k and owner[ib] == k and owner[ib + 1] == k:
        color[k] = round_id
    else:
        wp.atomic_add(remaining, 0, 1)


@wp.kernel
def warm_start_rod_contacts(
    count: int,
    key: wp.array(dtype=wp.int64),
    normal: wp.array(dtype=wp.vec3d),
    prev_count: int,
    prev_key: wp.array(dtype=wp.int64),
    prev_impulse: wp.array(dtype=wp.vec3d),
    warm: wp.float64,
    impulse: wp.array(dtype=wp.vec3d),
):
    """Reuse last step's impulse of the same contact (keys are sorted: binary search).

    The old impulse is split along the new normal; its tangential part is kept, as friction
    that held last step should hold from the first iteration of this one.
    """
    k = wp.tid()
    if k >= count:
        return
    target = key[k]
    lo = int(0)
    hi = prev_count
    while lo < hi:
        mid = (lo + hi) // 2
        if prev_key[mid] < target:
            lo = mid + 1
        else:
            hi = mid
    p = wp.vec3d(F0, F0, F0)
    if lo < prev_count:
        if prev_key[lo] == target:
            old = prev_impulse[lo]
            n = normal[k]
            pn = wp.max(wp.dot(old, n), F0)
            pt = old - n * wp.dot(old, n)
            p = (n * pn + pt) * warm
    impulse[k] = p
