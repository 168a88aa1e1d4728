"""Contact and Coulomb friction by projected Gauss-Seidel on velocities (Moreau-Jean).

Each contact holds an accumulated impulse P (N s).  One visit solves the contact's local
problem exactly: the velocity-weighted inverse mass of a point on a segment is isotropic
(w I), so non-penetration decouples from friction and the Coulomb cone |P_t| <= mu P_n is
met by projecting P_t onto a disc: the exact cone, no pyramid, and true sticking (the
tangential relative velocity is driven to zero whenever the disc is not reached).

Contacts that share a vertex must not be visited concurrently.  On the CPU a launch runs its
threads in order, which is plain sequential Gauss-Seidel; on a GPU the contacts are
coloured first (``color_claim`` / ``color_commit``) and each colour is one launch.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)
F1 = wp.float64(1.0)


@wp.func
def approach_target(gap: wp.float64, dt: wp.float64, beta: wp.float64, max_push: wp.float64):
    """Lowest normal relative velocity allowed this step (m/s)."""
    if gap >= F0:
        return -gap / dt
    return wp.min(-beta * gap / dt, max_push)


@wp.func
def solve_rod_contact(
    k: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    st: wp.array(dtype=wp.vec2d),
    normal: wp.array(dtype=wp.vec3d),
    gap: wp.array(dtype=wp.float64),
    inv_mass: wp.array(dtype=wp.float64),
    mu: wp.float64,
    dt: wp.float64,
    beta: wp.float64,
    max_push: wp.float64,
    impulse: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
):
    """Exact local solve of rod-rod contact k; returns the velocity change it caused (m/s)."""
    sp = seg[k]
    ia = seg_vertex[sp[0]]
    ib = seg_vertex[sp[1]]
    s = st[k][0]
    t = st[k][1]
    a0 = F1 - s
    a1 = s
    b0 = F1 - t
    b1 = t
    wa0 = inv_mass[ia] * a0
    wa1 = inv_mass[ia + 1] * a1
    wb0 = inv_mass[ib] * b0
    wb1 = inv_mass[ib + 1] * b1
    w = wa0 * a0 + wa1 * a1 + wb0 * b0 + wb1 * b1
    if w <= F0:
        return F0
    n = normal[k]
    u = v[ia] * a0 + v[ia + 1] * a1 - v[ib] * b0 - v[ib + 1] * b1
    P = impulse[k]
    pn = wp.dot(P, n)
    pt = P - n * pn
    target = approach_target(gap[k], dt, beta, max_push)
    un = wp.dot(u, n)
    pn_new = wp.max(F0, pn + (target - un) / w)
    u = u + n * ((pn_new - pn) * w)
    ut = u - n * wp.dot(u, n)
    pt_new = pt - ut / w
    lim = mu * pn_new
    ptl = wp.length(pt_new)
    if ptl > lim:
        if ptl > F0:
            pt_new = pt_new * (lim / ptl)
    dP = n * (pn_new - pn) + (pt_new - pt)
    v[ia] = v[ia] + dP * wa0
    v[ia + 1] = v[ia + 1] + dP * wa1
    v[ib] = v[ib] - dP * wb0
    v[ib + 1] = v[ib + 1] - dP * wb1
    impulse[k] = n * pn_new + pt_new
    return wp.length(dP) * w


@wp.kernel
def solve_rod_contacts(
    ids: wp.array(dtype=wp.int32),
    use_ids: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    st: wp.array(dtype=wp.vec2d),
    normal: wp.array(dtype=wp.vec3d),
    gap: wp.array(dtype=wp.float64),
    inv_mass: wp.array(dtype=wp.float64),
    mu: wp.float64,
    dt: wp.float64,
    beta: wp.float64,
    max_push: wp.float64,
    impulse: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    residual: wp.array(dtype=wp.float64),
):
    """One thread per contact of one colour (GPU) or of all contacts in order (CPU)."""
    k = wp.tid()
    if use_ids != 0:
        k = ids[k]
    du = solve_rod_contact(k, seg, seg_vertex, st, normal, gap, inv_mass, mu, dt, beta, max_push, impulse, v)
    wp.atomic_max(residual, 0, du)


@wp.kernel
def apply_rod_impulses(
    count: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    st: wp.array(dtype=wp.vec2d),
    inv_mass: wp.array(dtype=wp.float64),
    impulse: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
):
    """Warm start: apply the reused impulses once before iterating (atomics: any order)."""
    k = wp.tid()
    if k >= count:
        return
    sp = seg[k]
    ia = seg_vertex[sp[0]]
    ib = seg_vertex[sp[1]]
    s = st[k][0]
    t = st[k][1]
    P = impulse[k]
    wp.atomic_add(v, ia, P * ((F1 - s) * inv_mass[ia]))
    wp.atomic_add(v, ia + 1, P * (s * inv_mass[ia + 1]))
    wp.atomic_sub(v, ib, P * ((F1 - t) * inv_mass[ib]))
    wp.atomic_sub(v, ib + 1, P * (t * inv_mass[ib + 1]))


@wp.kernel
def prepare_plane_contacts(
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    vertex_rod: wp.array(dtype=wp.int32),
    rod_radius: wp.array(dtype=wp.float64),
    inv_mass: wp.array(dtype=wp.float64),
    plane_normal: wp.array(dtype=wp.vec3d),
    plane_offset: wp.array(dtype=wp.float64),
    plane_vel: wp.array(dtype=wp.vec3d),
    n_planes: int,
    base_margin: wp.float64,
    dt: wp.float64,
    warm: wp.float64,
    plane_gap: wp.array(dtype=wp.float64),
    plane_impulse: wp.array(dtype=wp.vec3d),
    v_out: wp.array(dtype=wp.vec3d),
    active: wp.array(dtype=wp.int32),
    n_active: wp.array(dtype=wp.int32),
):
    """Per vertex: gaps to every plane at the start of the step; warm-started impulses;
    the vertex joins the ``active`` list when any plane is within reach.

    A capsule touches a plane first at a segment endpoint, so vertex spheres suffice.
    Inactive contacts get gap = +inf and zero impulse.
    """
    i = wp.tid()
    r = rod_radius[vertex_rod[i]]
    vi = v[i]
    dv = wp.vec3d(F0, F0, F0)
    any_active = int(0)
    for p in range(n_planes):
        k = i * n_planes + p
        n = plane_normal[p]
        g = wp.dot(n, x[i]) - plane_offset[p] - r
        closing = wp.max(-wp.dot(vi - plane_vel[p], n), F0)
        if g < base_margin + closing * dt * wp.float64(2.0):
            plane_gap[k] = g
            P = plane_impulse[k] * warm
            pn = wp.max(wp.dot(P, n), F0)
            P = n * pn + (P - n * wp.dot(P, n))
            plane_impulse[k] = P
            dv = dv + P * inv_mass[i]
            any_active = 1
        else:
            plane_gap[k] = wp.float64(1.0e300)
            plane_impulse[k] = wp.vec3d(F0, F0, F0)
    v_out[i] = v_out[i] + dv
    if any_active != 0:
        active[wp.atomic_add(n_active, 0, 1)] = i


@wp.func
def solve_vertex_planes(
    i: int,
    inv_mass: wp.array(dtype=wp.float64),
    plane_normal: wp.array(dtype=wp.vec3d),
    plane_vel: wp.array(dtype=wp.vec3d),
    plane_mu: wp.array(dtype=wp.float64),
    n_planes: int,
    plane_gap: wp.array(dtype=wp.float64),
    dt: wp.float64,
    beta: wp.float64,
    max_push: wp.float64,
    plane_impulse: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
):
    """Every active plane of vertex i in turn (same exact local solve as rod-rod contacts);
    returns the largest velocity change caused (m/s)."""
    w = inv_mass[i]
    worst = F0
    if w <= F0:
        return worst
    for p in range(n_planes):
        k = i * n_planes + p
        g = plane_gap[k]
        if g > wp.float64(1.0e299):
            continue
        n = plane_normal[p]
        u = v[i] - plane_vel[p]
        P = plane_impulse[k]
        pn = wp.dot(P, n)
        pt = P - n * pn
        target = approach_target(g, dt, beta, max_push)
        pn_new = wp.max(F0, pn + (target - wp.dot(u, n)) / w)
        u = u + n * ((pn_new - pn) * w)
        ut = u - n * wp.dot(u, n)
        pt_new = pt - ut / w
        lim = plane_mu[p] * pn_new
        ptl = wp.length(pt_new)
        if ptl > lim:
            if ptl > F0:
                pt_new = pt_new * (lim / ptl)
        dP = n * (pn_new - pn) + (pt_new - pt)
        v[i] = v[i] + dP * w
        plane_impulse[k] = n * pn_new + pt_new
        worst = wp.max(worst, wp.length(dP) * w)
    return worst


@wp.kernel
def solve_plane_contacts(
    active: wp.array(dtype=wp.int32),
    inv_mass: wp.array(dtype=wp.float64),
    plane_normal: wp.array(dtype=wp.vec3d),
    plane_vel: wp.array(dtype=wp.vec3d),
    plane_mu: wp.array(dtype=wp.float64),
    n_planes: int,
    plane_gap: wp.array(dtype=wp.float64),
    dt: wp.float64,
    beta: wp.float64,
    max_push: wp.float64,
    plane_impulse: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    residual: wp.array(dtype=wp.float64),
):
    """One thread per vertex that touches a wall (``active`` lists them)."""
    i = active[wp.tid()]
    du = solve_vertex_planes(i, inv_mass, plane_normal, plane_vel, plane_mu, n_planes, plane_gap, dt, beta,
                             max_push, plane_impulse, v)
    wp.atomic_max(residual, 0, du)


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
