"""Contact and Coulomb friction at the rods' surfaces, by projected Gauss-Seidel on velocities.

Each contact holds an accumulated impulse P (N s) acting at the two surface points
(x_a(s) - r_a n on rod a, x_b(t) + r_b n on rod b; n points from b to a); the local problem
of one contact is solved exactly, so a sweep is block Gauss-Seidel with exact blocks.

The velocity of a surface point, and how it responds to an impulse there (the mobility W,
3 x 3), come from the rod model:

* elastic rods: the centreline velocity interpolated on the edge plus the edge's spin omega
  about its tangent t acting on the surface offset o (= -r n on rod a): u = v(s) + omega t x o;
  W = w I + (1 / I_edge) (t x o)(t x o)^T, w the point's entry of the tridiagonal inverse mass;
* rigid rods: the exact rigid-body mobility of the capsule at the point, lever r from its
  centre of mass: W = I / m - [r]x I^-1 [r]x with I^-1 = (I - t t^T) / I_perp + t t^T / I_axis,
  and the impulse applied as a rigid-body velocity change (translation, rotation across the
  axis on the two vertices, spin about it), so contacts never fight the rod's length
  constraint (a two-vertex rod with its vertex inverse masses would, and Gauss-Seidel would
  converge slowly on every axial load: a rod standing on its end, a pile's side walls).

The contact problem with W = W_a + W_b is the contact law's (:mod:`rodwarp.kernels.contact_laws`
tags them): the exact law (:mod:`rodwarp.kernels.exact`: Signorini and the Coulomb cone, true
sticking) or IMC (:mod:`rodwarp.kernels.imc`: a smooth penalty and smoothed friction).
:func:`solve_contact` asks the law for a closed-form answer first, then alternates the normal
and the tangential part, each solved by the law with the other held, where W couples them
(rigid rods, contacts off the segments' interiors).

Contacts that share a vertex (hence an edge) must not be visited concurrently. On the CPU a
launch runs its threads in order (sequential Gauss-Seidel); on a GPU rod-rod contacts are
coloured first (``color_claim`` / ``color_commit``) and each colour is one launch, and wall
contacts run one thread per rod.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF, FAR
from rodwarp.kernels import contact_laws
from rodwarp.kernels.narrowphase import any_perpendicular
from rodwarp.kernels.structs import ContactFrame, ContactSide, RodContacts, RodModel, StepParams

wp.set_module_options({"enable_backward": False})


@wp.func
def approach_target(gap: wp.float64, params: StepParams):
    """Lowest normal relative velocity allowed this step (m/s): close an open gap at most to
    touching; an overlap is not pushed apart by velocity (the position projection after the
    step removes it), so a resting contact's velocity problem repeats from step to step."""
    if gap >= F0:
        return -gap / params.dt
    return F0


@wp.func
def restitution_target(target: wp.float64, gap: wp.float64, vn: wp.float64, params: StepParams):
    """Newton restitution (``params.restitution`` e > 0): a contact approaching faster than
    ``params.bounce_speed`` at the start of the step (normal relative velocity ``vn`` < -v_min,
    before any contact impulse of the step) that touches or closes within it
    (gap + vn dt <= 0) must leave at least at -e vn; otherwise ``target`` (the
    :func:`approach_target`) stands. Callers call it only when e > 0, so e = 0 is the law as
    it was, bit for bit."""
    if vn < -params.bounce_speed and gap + vn * params.dt <= F0:
        return wp.max(target, -params.restitution * vn)
    return target


@wp.func
def local_frame(W: wp.mat33d, n: wp.vec3d, target: wp.float64):
    """The parts of a contact's local problem fixed within a step: mobility, tangent basis,
    the mobility's entries in it, whether normal and tangent couple, the normal target."""
    f = ContactFrame()
    f.W = W
    e1 = any_perpendicular(n)
    e2 = wp.cross(n, e1)
    f.e1 = e1
    Wn = W * n
    wnn = wp.dot(n, Wn)
    f.k = wp.vec4d(wnn, wp.dot(e1, W * e1), wp.dot(e1, W * e2), wp.dot(e2, W * e2))
    # coupling of normal and tangential parts (zero for an elastic contact at the segments' interiors)
    f.coupled = int(wp.abs(wp.dot(e1, Wn)) + wp.abs(wp.dot(e2, Wn)) > wp.float64(1.0e-12) * wnn)
    f.target = target
    # W is symmetric positive semi-definite; it is singular only where both sides are (nearly)
    # immobile in some direction (pinned vertices), and then the sticking shortcut is skipped
    tr = W[0, 0] + W[1, 1] + W[2, 2]
    if wp.determinant(W) > wp.float64(1.0e-9) * tr * tr * tr:
        f.Winv = wp.inverse(W)
    return f


@wp.func
def solve_contact(u: wp.vec3d, f: ContactFrame, n: wp.vec3d, P: wp.vec3d, mu: wp.float64, params: StepParams):
    """The impulse of one contact under the step's contact law (``params.law``, a tag of
    :mod:`rodwarp.kernels.contact_laws`): u the contact velocity with the current impulse P
    applied, ``f`` its :func:`local_frame`; returns the new impulse and the law's friction
    guess for the next sweep, kept in the frame (the exact law's sliding multiplier gamma, 0
    unless it slides; IMC's slip speed).

    The law may settle the contact in closed form (the exact law: no approach, or sticking);
    otherwise the normal and the tangential part alternate, each solved exactly by the law
    with the other held, where the mobility couples them (rigid rods, contacts at segment
    ends).
    """
    wnn = f.k[0]
    if wnn <= F0:
        return P, f.gamma
    W = f.W
    uf = u - W * P  # the velocity this contact's impulse acts on
    law = params.law
    lp = params.law_params
    solved, P_closed, guess_closed = contact_laws.closed_form(law, uf, n, f.target, f.Winv, mu, lp)
    if solved != 0:
        return P_closed, guess_closed
    rounds, tol, idle = contact_laws.settings(law)
    e1 = f.e1
    e2 = wp.cross(n, e1)
    pn = wp.dot(P, n)
    pt = P - n * pn
    guess = f.gamma
    for it in range(rounds):
        cn = wp.dot(uf + W * pt, n)  # normal velocity with the tangential part held
        pn_new = contact_laws.normal_impulse(law, f.gap, f.target, cn, wnn, pn, params.dt, lp)
        c = uf + (W * n) * pn_new
        c1 = wp.dot(c, e1)
        c2 = wp.dot(c, e2)
        q = contact_laws.friction_impulse(law, c1, c2, f.k[1], f.k[2], f.k[3], mu * pn_new, guess, lp)
        guess = q[2]
        pt_new = e1 * q[0] + e2 * q[1]
        change = wp.abs(pn_new - pn) + wp.length(pt_new - pt)
        pn = pn_new
        pt = pt_new
        if f.coupled == 0 or change <= tol * (pn + wp.length(pt)):
            break
    return n * pn + pt, guess


@wp.func
def point_weights(w0: wp.float64, w1: wp.float64, c: wp.float64, s: wp.float64):
    """Rows of the tridiagonal M^-1 at a point (1 - s, s) of an edge: the velocity change of
    each end per unit impulse, and the point's own inverse mass."""
    q0 = (F1 - s) * w0 + s * c
    q1 = (F1 - s) * c + s * w1
    return q0, q1, (F1 - s) * q0 + s * q1


@wp.func
def contact_side(model: RodModel, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d), i: int,
                 s: wp.float64, off: wp.vec3d):
    """The side of a contact at x(s) + off on the edge starting at vertex i, and the mobility
    of that point (m / (N s))."""
    c = ContactSide()
    c.i = i
    c.s = s
    t = tangent[i]
    r = model.vertex_rod[i]
    c.rigid = model.rigid[r]
    if c.rigid != 0:
        c.lever = (x[i] - x[i + 1]) * HALF + (x[i + 1] - x[i]) * s + off
        ip = model.rod_inv_iperp[r]
        iinv = wp.diag(wp.vec3d(ip, ip, ip)) + wp.outer(t, t) * (model.inv_inertia[i] - ip)
        c.im = model.rod_inv_mass[r]
        R = wp.skew(c.lever)
        c.turn = iinv * R
        return c, wp.diag(wp.vec3d(c.im, c.im, c.im)) - R * c.turn
    q0, q1, w = point_weights(model.inv_mass[i], model.inv_mass[i + 1], model.cross_inv_mass[i], s)
    c.q0 = q0
    c.q1 = q1
    c.ispin = model.inv_inertia[i]
    c.lever = wp.cross(t, off)
    return c, wp.diag(wp.vec3d(w, w, w)) + wp.outer(c.lever, c.lever) * c.ispin


@wp.func
def side_velocity(c: ContactSide, v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64)):
    """Velocity of the side's material point (m/s), inside the sweeps (a rigid rod's velocity
    held as a body's: centre of mass at its first vertex, angular velocity at its second)."""
    i = c.i
    if c.rigid != 0:
        return v[i] + wp.cross(v[i + 1], c.lever)
    return v[i] * (F1 - c.s) + v[i + 1] * c.s + c.lever * spin[i]


@wp.func
def side_apply(c: ContactSide, P: wp.vec3d, v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64)):
    """Apply impulse P at the side's point, inside the sweeps (rigid rods as bodies)."""
    i = c.i
    if c.rigid != 0:
        v[i] = v[i] + P * c.im
        v[i + 1] = v[i + 1] + c.turn * P
    else:
        v[i] = v[i] + P * c.q0
        v[i + 1] = v[i + 1] + P * c.q1
        spin[i] = spin[i] + wp.dot(P, c.lever) * c.ispin
    return 0


@wp.func
def side_response(c: ContactSide, P: wp.vec3d, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d)):
    """Velocity changes of the side's two vertices and of its edge's spin for impulse P at its
    point, outside the sweeps (a rigid rod moved as a rigid body: translation, rotation across
    the axis on the two vertices about their midpoint at ``x``, spin about it)."""
    if c.rigid != 0:
        i = c.i
        t = tangent[i]
        dvc = P * c.im
        dw = c.turn * P
        ws = wp.dot(dw, t)
        turn = wp.cross(dw - t * ws, (x[i] - x[i + 1]) * HALF)
        return dvc + turn, dvc - turn, ws
    return P * c.q0, P * c.q1, wp.dot(P, c.lever) * c.ispin


@wp.func
def side_apply_atomic(c: ContactSide, P: wp.vec3d, x: wp.array(dtype=wp.vec3d), tangent: wp.array(dtype=wp.vec3d),
                      v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64)):
    """Apply impulse P at the side's point to the vertex velocities (outside the sweeps), with
    atomic adds for launches whose threads may share a rod."""
    dv0, dv1, ds = side_response(c, P, x, tangent)
    wp.atomic_add(v, c.i, dv0)
    wp.atomic_add(v, c.i + 1, dv1)
    wp.atomic_add(spin, c.i, ds)
    return 0


@wp.func
def rigid_to_body(r: int, model: RodModel, tangent: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d),
                  spin: wp.array(dtype=wp.float64), axial: wp.array(dtype=wp.float64)):
    """Rigid rod r's vertex velocities and spin as a body's for the sweeps: centre-of-mass
    velocity into its first vertex's slot, angular velocity (across the axis from the ends'
    relative velocity, plus the spin about it) into its second; the ends' relative velocity
    along the axis, which a rigid motion does not hold, kept in ``axial``. A contact then
    reads and changes a rigid rod in a few products (no division, no split of the turn)."""
    if model.rigid[r] == 0:
        return 0
    i = model.rod_start[r]
    t = tangent[i]
    d = v[i + 1] - v[i]
    axial[i] = wp.dot(d, t)
    v[i] = (v[i] + v[i + 1]) * HALF
    v[i + 1] = wp.cross(t, d) / model.rest_length[i] + t * spin[i]
    return 0


@wp.func
def rigid_from_body(r: int, model: RodModel, tangent: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d),
                    spin: wp.array(dtype=wp.float64), axial: wp.array(dtype=wp.float64)):
    """The inverse of :func:`rigid_to_body`: vertex velocities and spin again."""
    if model.rigid[r] == 0:
        return 0
    i = model.rod_start[r]
    t = tangent[i]
    w = v[i + 1]
    half = (wp.cross(w, t) * model.rest_length[i] + t * axial[i]) * HALF
    vc = v[i]
    v[i] = vc - half
    v[i + 1] = vc + half
    if model.inv_inertia[i] > F0:
        spin[i] = wp.dot(w, t)
    else:
        spin[i] = F0  # locked spin (no rolling) stays exactly zero
    return 0


@wp.kernel
def rigid_bodies_to_sweeps(model: RodModel, tangent: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d),
                           spin: wp.array(dtype=wp.float64), axial: wp.array(dtype=wp.float64)):
    """One thread per rod: :func:`rigid_to_body` (before the sweeps of a parallel device)."""
    rigid_to_body(wp.tid(), model, tangent, v, spin, axial)


@wp.kernel
def rigid_bodies_from_sweeps(model: RodModel, tangent: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d),
                             spin: wp.array(dtype=wp.float64), axial: wp.array(dtype=wp.float64)):
    """One thread per rod: :func:`rigid_from_body` (after the sweeps of a parallel device)."""
    rigid_from_body(wp.tid(), model, tangent, v, spin, axial)


@wp.func
def rod_contact_sides(k: int, model: RodModel, x: wp.array(dtype=wp.vec3d), contacts: RodContacts,
                      tangent: wp.array(dtype=wp.vec3d)):
    sp = contacts.seg[k]
    ia = model.seg_vertex[sp[0]]
    ib = model.seg_vertex[sp[1]]
    n = contacts.normal[k]
    a, Wa = contact_side(model, x, tangent, ia, contacts.st[k][0], n * (-model.radius[model.vertex_rod[ia]]))
    b, Wb = contact_side(model, x, tangent, ib, contacts.st[k][1], n * model.radius[model.vertex_rod[ib]])
    return a, b, Wa + Wb


@wp.func
def relaxed(P_new: wp.vec3d, P: wp.vec3d, n: wp.vec3d, mu: wp.float64, relax: wp.float64):
    """P + relax (P_new - P), projected back onto the friction cone (relax = 1: P_new)."""
    if relax == F1:
        return P_new
    R = P + (P_new - P) * relax
    rn = wp.dot(R, n)
    pn = wp.max(rn, F0)
    pt = R - n * rn
    lt2 = wp.dot(pt, pt)
    limit = mu * pn
    if lt2 > limit * limit:
        pt = pt * (limit / wp.sqrt(lt2))
    return n * pn + pt


@wp.kernel
def prepare_rod_contacts(model: RodModel, x: wp.array(dtype=wp.vec3d), contacts: RodContacts,
                         tangent: wp.array(dtype=wp.vec3d), params: StepParams, frames: wp.array(dtype=ContactFrame),
                         v0: wp.array(dtype=wp.vec3d), spin0: wp.array(dtype=wp.float64)):
    """Per contact, once per step: its two sides, mobility, tangent basis and normal target.
    ``v0``, ``spin0``: the velocities before this step's contact impulses, rigid rods as bodies
    (:func:`rigid_to_body`), read only with restitution (:func:`restitution_target`)."""
    k = wp.tid()
    if k >= contacts.count:
        return
    a, b, W = rod_contact_sides(k, model, x, contacts, tangent)
    n = contacts.normal[k]
    target = approach_target(contacts.gap[k], params)
    if params.restitution > F0:
        vn = wp.dot(side_velocity(a, v0, spin0) - side_velocity(b, v0, spin0), n)
        target = restitution_target(target, contacts.gap[k], vn, params)
    f = local_frame(W, n, target)
    f.gap = contacts.gap[k]
    f.a = a
    f.b = b
    frames[k] = f


@wp.func
def rod_contact_exact(f: ContactFrame, P: wp.vec3d, n: wp.vec3d, params: StepParams, v: wp.array(dtype=wp.vec3d),
                      spin: wp.array(dtype=wp.float64)):
    """The exact local impulse of a rod-rod contact (frame ``f``, impulse ``P``, normal ``n``)
    against the current velocities, the other contacts held fixed."""
    return solve_contact(side_velocity(f.a, v, spin) - side_velocity(f.b, v, spin), f, n, P, params.mu, params)


@wp.func
def solve_rod_contact(k: int, frames: wp.array(dtype=ContactFrame), impulse: wp.array(dtype=wp.vec3d),
                      normal: wp.array(dtype=wp.vec3d), params: StepParams, v: wp.array(dtype=wp.vec3d),
                      spin: wp.array(dtype=wp.float64)):
    """Exact local solve of rod-rod contact k (its frame, accumulated impulse and normal);
    returns the square of the velocity change it caused (m^2/s^2: the sweep's largest is
    rooted once, not every contact's). Takes the arrays it reads rather than the model and
    contact bundles: the innermost call of every sweep, so nothing else is copied."""
    P = impulse[k]
    n = normal[k]
    rounds, tol, idle = contact_laws.settings(params.law)
    if idle != 0 and P[0] == F0 and P[1] == F0 and P[2] == F0:
        # an idle contact (no impulse yet) that does not approach faster than its target gets
        # none under a law that says so (the exact law): what the solve below returns, without
        # copying the whole frame or touching the rods (most speculative contacts of a pile are
        # idle in most sweeps)
        if frames[k].k[0] > F0:
            u = side_velocity(frames[k].a, v, spin) - side_velocity(frames[k].b, v, spin)
            if wp.dot(u, n) >= frames[k].target:
                frames[k].gamma = F0
                return F0
    f = frames[k]
    P_exact, gamma = rod_contact_exact(f, P, n, params, v, spin)
    frames[k].gamma = gamma
    P_new = relaxed(P_exact, P, n, params.mu, params.relax)
    dP = P_new - P
    side_apply(f.a, dP, v, spin)
    side_apply(f.b, -dP, v, spin)
    impulse[k] = P_new
    du = f.W * dP
    return wp.dot(du, du)


@wp.kernel
def solve_rod_contacts(ids: wp.array(dtype=wp.int32), use_ids: int, model: RodModel, contacts: RodContacts,
                       frames: wp.array(dtype=ContactFrame), params: StepParams, v: wp.array(dtype=wp.vec3d),
                       spin: wp.array(dtype=wp.float64), residual: wp.array(dtype=wp.float64)):
    """One thread per contact of one colour (GPU) or of all contacts in order (CPU); the
    residual as the square of the largest velocity change (m^2/s^2)."""
    k = wp.tid()
    if use_ids != 0:
        k = ids[k]
    wp.atomic_max(residual, 0, solve_rod_contact(k, frames, contacts.impulse, contacts.normal, params, v, spin))


@wp.kernel
def apply_rod_impulses(contacts: RodContacts, frames: wp.array(dtype=ContactFrame), x: wp.array(dtype=wp.vec3d),
                       tangent: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64)):
    """Warm start: apply the reused impulses once before iterating (atomics: any order)."""
    k = wp.tid()
    if k >= contacts.count:
        return
    P = contacts.impulse[k]
    side_apply_atomic(frames[k].a, P, x, tangent, v, spin)
    side_apply_atomic(frames[k].b, -P, x, tangent, v, spin)


# ----------------------------------------------------------------------------- diagnostics


@wp.kernel
def rod_contact_residual(contacts: RodContacts, frames: wp.array(dtype=ContactFrame), params: StepParams,
                         v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64),
                         residual: wp.array(dtype=wp.float64)):
    """Per rod-rod contact, read only: the velocity change (m/s) its exact local solve would
    make against the current velocities (the Gauss-Seidel residual of every contact)."""
    k = wp.tid()
    if k >= contacts.count:
        return
    f = frames[k]
    P = contacts.impulse[k]
    P_exact, gamma = rod_contact_exact(f, P, contacts.normal[k], params, v, spin)
    wp.atomic_max(residual, 0, wp.length(f.W * (P_exact - P)))
