"""Rod elastics: bending, stretching and twist, each solved exactly per rod.

Bending
    Discrete isotropic bending energy of a polyline with rest edge lengths h_j,

        E_b = sum_i  (E I / (2 l_i)) |kappa_i - T_i|^2,
        kappa_i = (x_{i+1} - x_i) / h_i - (x_i - x_{i-1}) / h_{i-1},   l_i = (h_{i-1} + h_i) / 2,

    T_i the rest curvature vector in the current material frame (0 for straight rods,
    :mod:`rodwarp.kernels.frames`). It equals the discrete-elastic-rod energy
    E I (2 tan(theta_i / 2))^2 / (2 l_i) to second order in the turning angle for
    inextensible edges. kappa is linear in x with a constant stencil, so the implicit step
    of a straight rod costs one banded (pentadiagonal, three right-hand sides) solve.

Stretching
    Edge lengths are compliant constraints C_j = |x_{j+1} - x_j| - h_j with compliance
    h_j / (E A) (XPBD) along the start-of-step edge directions (SHAKE), a tridiagonal solve
    per rod: no explicit axial limit dt < h / sqrt(E / rho).

Twist
    Each edge carries a material angle theta_j and spin omega_j = d(theta_j)/dt with axial
    moment of inertia I_j = m_j r^2 / 2. The twist constraint at interior vertex i,
    C = theta_i - theta_{i-1} + (reference twist) - (rest twist), has compliance
    l_i / (G J), J = pi r^4 / 2: a tridiagonal solve per rod, unconditionally stable, so the
    stiff torsion of steel does not limit the step.

Curved rods
    T_i turns with the material angles, dT_i/dtheta_j = b_i x T_i / 2 for j = i-1, i, so
    bending and twist are coupled: the multipliers of both (4 per interior vertex) form one
    symmetric block-pentadiagonal system of 4 x 4 blocks, factored once per step
    (block LDL^T) and solved exactly in every Gauss-Seidel sweep.

Every block works on the predicted configuration (x + dt v, theta + dt omega) and changes
velocities only (XPBD in velocity form), so contacts and elastics share one velocity state
and one mass metric inside the sweep and the converged step is implicit Euler.
"""

import warp as wp

from rodwarp.kernels.constants import F0, F1, HALF
from rodwarp.kernels.structs import RodFactors, RodModel, RodState

wp.set_module_options({"enable_backward": False})


@wp.func
def bend_coeffs(rest_length: wp.array(dtype=wp.float64), i: int):
    """Stencil (c_-1, c_0, c_+1) of kappa_i at interior vertex i and the weight 1 / l_i."""
    hm = rest_length[i - 1]
    hp = rest_length[i]
    cm = F1 / hm
    cp = F1 / hp
    return cm, -(cm + cp), cp, wp.float64(2.0) / (hm + hp)


# ----------------------------------------------------------------------------- predictor


@wp.kernel
def velocity_predictor(model: RodModel, state: RodState, btarget: wp.array(dtype=wp.vec3d),
                       torque: wp.array(dtype=wp.float64), body_accel: wp.vec3d, damping: wp.float64, dt: wp.float64,
                       explicit_bending: int, v_out: wp.array(dtype=wp.vec3d), spin_out: wp.array(dtype=wp.float64)):
    """One thread per rod: velocity after damping, body force, (explicit) bending; spin after
    damping and the applied axial torques (N m per edge).

    Damping first decays the old velocity, v / (1 + gamma dt), so that static forces, and
    the constraint forces that balance them, are not scaled by it. Implicit bending is not
    applied here but inside the Gauss-Seidel sweep, so every block uses the same mass metric
    and the fixed point of the step is the true static equilibrium.
    """
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    decay = F1 / (F1 + damping * dt)
    for i in range(a, b):
        if model.inv_mass[i] == F0:
            v_out[i] = state.v[i]
        else:
            v_out[i] = state.v[i] * decay + body_accel * dt
        if model.inv_inertia[i] > F0:
            spin_out[i] = state.spin[i] * decay + torque[i] * model.inv_inertia[i] * dt
        else:
            spin_out[i] = F0
    if explicit_bending != 0 and b - a >= 3:
        EI = model.bend_stiffness[r]
        for i in range(a + 1, b - 1):
            cm, c0, cp, wl = bend_coeffs(model.rest_length, i)
            kap = state.x[i - 1] * cm + state.x[i] * c0 + state.x[i + 1] * cp - btarget[i]
            f = kap * (EI * wl * dt)
            v_out[i - 1] = v_out[i - 1] - f * (cm * model.inv_mass[i - 1])
            v_out[i] = v_out[i] - f * (c0 * model.inv_mass[i])
            v_out[i + 1] = v_out[i + 1] - f * (cp * model.inv_mass[i + 1])


# ----------------------------------------------------------------------------- factors


@wp.func
def pentadiagonal_factor(a: int, b: int, diag: wp.array(dtype=wp.float64), off1: wp.array(dtype=wp.float64),
                         off2: wp.array(dtype=wp.float64)):
    """In-place LDL^T of the SPD pentadiagonal matrix on rows [a, b).

    diag -> 1 / D (the solves multiply by it: a division in every sweep's chain of
    substitutions costs more than the rest of the row), off1 (row i with i+1) -> L[i+1, i],
    off2 (row i with i+2) -> L[i+2, i].
    """
    for i in range(a, b):
        d = diag[i]
        if i - 1 >= a:
            l1m = off1[i - 1]
            d = d - l1m * l1m * diag[i - 1]
        if i - 2 >= a:
            l2mm = off2[i - 2]
            d = d - l2mm * l2mm * diag[i - 2]
        diag[i] = d
        if i + 1 < b:
            t = off1[i]
            if i - 1 >= a:
                t = t - off1[i - 1] * off2[i - 1] * diag[i - 1]
            off1[i] = t / d
        if i + 2 < b:
            off2[i] = off2[i] / d
    for i in range(a, b):
        diag[i] = F1 / diag[i]
    return 0


@wp.func
def pentadiagonal_substitute(a: int, b: int, dinv: wp.array(dtype=wp.float64), off1: wp.array(dtype=wp.float64),
                             off2: wp.array(dtype=wp.float64), rhs: wp.array(dtype=wp.vec3d),
                             out: wp.array(dtype=wp.vec3d)):
    """Solve with the factors of ``pentadiagonal_factor`` (``dinv`` = 1 / D) for three
    right-hand sides (rhs is overwritten by the forward substitution)."""
    for i in range(a, b):
        z = rhs[i]
        if i - 1 >= a:
            z = z - rhs[i - 1] * off1[i - 1]
        if i - 2 >= a:
            z = z - rhs[i - 2] * off2[i - 2]
        rhs[i] = z
    for k in range(b - a):
        i = b - 1 - k
        y = rhs[i] * dinv[i]
        if i + 1 < b:
            y = y - out[i + 1] * off1[i]
        if i + 2 < b:
            y = y - out[i + 2] * off2[i]
        out[i] = y
    return 0


@wp.kernel
def bending_factor(model: RodModel, dt: wp.float64, factors: RodFactors):
    """One thread per straight rod: LDL^T of J W J^T + alpha / dt^2 of its bending constraints.

    Also stores each constraint's stencil and alpha / dt^2 in ``bend_stencil`` so the iterations
    need no divisions. kappa_i is linear in x, so this matrix depends only on masses, rest
    lengths, E I and dt: factored once per step size and reused by every step.
    """
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    if b - a < 3 or model.curved[r] != 0:
        return
    EI = model.bend_stiffness[r]
    inv_dt2 = F1 / (dt * dt)
    for i in range(a + 1, b - 1):
        cm, c0, cp, wl = bend_coeffs(model.rest_length, i)
        w0 = model.inv_mass[i]
        wq = model.inv_mass[i + 1]
        at = inv_dt2 / (EI * wl)
        factors.bend_stencil[i] = wp.vec4d(cm, c0, cp, at)
        factors.bend_inv_pivot[i] = cm * cm * model.inv_mass[i - 1] + c0 * c0 * w0 + cp * cp * wq + at
        factors.bend_lower1[i] = F0
        factors.bend_lower2[i] = F0
        if i + 1 < b - 1:
            dm, d0, dp, wl1 = bend_coeffs(model.rest_length, i + 1)
            factors.bend_lower1[i] = c0 * dm * w0 + cp * d0 * wq
        if i + 2 < b - 1:
            em, e0, ep, wl2 = bend_coeffs(model.rest_length, i + 2)
            factors.bend_lower2[i] = cp * em * wq
    pentadiagonal_factor(a + 1, b - 1, factors.bend_inv_pivot, factors.bend_lower1, factors.bend_lower2)


@wp.kernel
def stretch_twist_factor(model: RodModel, x: wp.array(dtype=wp.vec3d), dt: wp.float64, factors: RodFactors):
    """One thread per rod, once per step: edge directions at the start of the step and the
    Thomas factors of the edge-length constraints and (straight rods) of the twist
    constraints.

    SHAKE: stretch corrections act along the start-of-step edges (fixed during the step),
    which keeps the scheme symplectic (no energy drift) and the matrix constant in the step.
    A single-edge (rigid) rod's consistent mass enters through its cross term.
    """
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    inv_dt2 = F1 / (dt * dt)
    for j in range(a, b - 1):
        e0 = x[j + 1] - x[j]
        l0 = wp.length(e0)
        nj = wp.vec3d(F0, F0, F0)
        if l0 > F0:
            nj = e0 / l0
        factors.stretch_dir[j] = nj
    off_prev = F0
    for j in range(a, b - 1):
        d = model.inv_mass[j] + model.inv_mass[j + 1] - wp.float64(2.0) * model.cross_inv_mass[j] + \
            model.compliance[j] * inv_dt2
        off = F0
        if j + 1 < b - 1:
            off = -model.inv_mass[j + 1] * wp.dot(factors.stretch_dir[j], factors.stretch_dir[j + 1])
        if d <= wp.float64(1.0e-300):
            # both ends pinned: a row that changes nothing
            d = F1
            off = F0
        if j > a:
            d = d - off_prev * factors.stretch_lower[j - 1]
        factors.stretch_inv_pivot[j] = F1 / d
        factors.stretch_lower[j] = off / d
        off_prev = off
    if model.curved[r] != 0:
        return
    off_prev = F0
    for i in range(a + 1, b - 1):
        d = model.inv_inertia[i - 1] + model.inv_inertia[i] + model.twist_compliance[i] * inv_dt2
        off = F0
        if i + 1 < b - 1:
            off = -model.inv_inertia[i]
        if i > a + 1:
            d = d - off_prev * factors.twist_lower[i - 1]
        factors.twist_inv_pivot[i] = F1 / d
        factors.twist_lower[i] = off / d
        off_prev = off


@wp.func
def coupled_block(model: RodModel, factors: RodFactors, inv_dt2: wp.float64, i: int, k: int):
    """Block (i, k), k in {i, i+1, i+2}, of J W J^T + alpha / dt^2 for the bending (rows 0-2)
    and twist (row 3) constraints of interior vertices i and k of a curved rod."""
    A = wp.mat44d()
    cm, c0, cp, wl = bend_coeffs(model.rest_length, i)
    g = factors.curved_coupling[i]
    if k == i:
        xs = cm * cm * model.inv_mass[i - 1] + c0 * c0 * model.inv_mass[i] + cp * cp * model.inv_mass[i + 1]
        wm = model.inv_inertia[i - 1]
        wq = model.inv_inertia[i]
        bb = wp.diag(wp.vec3d(xs, xs, xs)) + wp.outer(g, g) * (wm + wq) + \
            wp.diag(wp.vec3d(F1, F1, F1)) * (inv_dt2 / (model.bend_stiffness[model.vertex_rod[i]] * wl))
        bt = g * (-(wq - wm))
        tt = wm + wq + model.twist_compliance[i] * inv_dt2
        for p in range(3):
            for q in range(3):
                A[p, q] = bb[p, q]
            A[p, 3] = bt[p]
            A[3, p] = bt[p]
        A[3, 3] = tt
    elif k == i + 1:
        dm, d0, dp, wl1 = bend_coeffs(model.rest_length, k)
        gk = factors.curved_coupling[k]
        wq = model.inv_inertia[i]  # the edge the two vertices share
        xs = c0 * dm * model.inv_mass[i] + cp * d0 * model.inv_mass[i + 1]
        bb = wp.diag(wp.vec3d(xs, xs, xs)) + wp.outer(g, gk) * wq
        bt = g * wq  # bending i with twist k through theta_i (d C_k / d theta_i = -1)
        tb = gk * (-wq)  # twist i with bending k through theta_i
        for p in range(3):
            for q in range(3):
                A[p, q] = bb[p, q]
            A[p, 3] = bt[p]
            A[3, p] = tb[p]
        A[3, 3] = -wq
    else:
        em, e0, ep, wl2 = bend_coeffs(model.rest_length, k)
        xs = cp * em * model.inv_mass[i + 1]
        for p in range(3):
            A[p, p] = xs
    return A


@wp.kernel
def curved_factor(model: RodModel, dt: wp.float64, factors: RodFactors):
    """One thread per curved rod, once per step: block LDL^T of the coupled bending-twist
    system (blocks from :func:`coupled_block`; stores D, D^-1, L[i+1, i], L[i+2, i])."""
    r = wp.tid()
    if model.curved[r] == 0:
        return
    a = model.rod_start[r] + 1
    b = model.rod_start[r + 1] - 1
    inv_dt2 = F1 / (dt * dt)
    for i in range(a, b):
        D = coupled_block(model, factors, inv_dt2, i, i)
        if i - 1 >= a:
            L1 = factors.curved_lower1[i - 1]
            D = D - L1 * factors.curved_pivot[i - 1] * wp.transpose(L1)
        if i - 2 >= a:
            L2 = factors.curved_lower2[i - 2]
            D = D - L2 * factors.curved_pivot[i - 2] * wp.transpose(L2)
        Dinv = wp.inverse(D)
        factors.curved_pivot[i] = D
        factors.curved_inv_pivot[i] = Dinv
        if i + 1 < b:
            # A[i+1, i] = A[i, i+1]^T
            T = wp.transpose(coupled_block(model, factors, inv_dt2, i, i + 1))
            if i - 1 >= a:
                T = T - factors.curved_lower2[i - 1] * factors.curved_pivot[i - 1] * wp.transpose(
                    factors.curved_lower1[i - 1])
            factors.curved_lower1[i] = T * Dinv
        if i + 2 < b:
            factors.curved_lower2[i] = wp.transpose(coupled_block(model, factors, inv_dt2, i, i + 2)) * Dinv


# ----------------------------------------------------------------------------- projections


@wp.func
def project_straight_bending(r: int, a: int, b: int, model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d),
                             factors: RodFactors, dt: wp.float64, inv_dt: wp.float64):
    for i in range(a + 1, b - 1):
        c = factors.bend_stencil[i]
        Cb = (state.x[i - 1] + v[i - 1] * dt) * c[0] + (state.x[i] + v[i] * dt) * c[1] + \
            (state.x[i + 1] + v[i + 1] * dt) * c[2]
        factors.bend_rhs[i] = -(Cb - factors.bend_target[i]) - factors.bend_lambda[i] * c[3]
    pentadiagonal_substitute(a + 1, b - 1, factors.bend_inv_pivot, factors.bend_lower1, factors.bend_lower2,
                             factors.bend_rhs, factors.bend_dlambda)
    for i in range(a + 1, b - 1):
        c = factors.bend_stencil[i]
        dlb = factors.bend_dlambda[i]
        factors.bend_lambda[i] = factors.bend_lambda[i] + dlb
        g = dlb * inv_dt
        v[i - 1] = v[i - 1] + g * (c[0] * model.inv_mass[i - 1])
        v[i] = v[i] + g * (c[1] * model.inv_mass[i])
        v[i + 1] = v[i + 1] + g * (c[2] * model.inv_mass[i + 1])
    return 0


@wp.func
def twist_residual(model: RodModel, state: RodState, spin: wp.array(dtype=wp.float64), factors: RodFactors,
                   dt: wp.float64, i: int):
    """Twist constraint C at interior vertex i at the predicted angles (rad)."""
    return (state.theta[i] + spin[i] * dt) - (state.theta[i - 1] + spin[i - 1] * dt) + factors.ref_twist[i] - \
        model.rest_twist[i]


@wp.func
def eliminated(r: wp.float64, l: wp.array(dtype=wp.float64), rhs: wp.array(dtype=wp.float64), i: int, lo: int):
    """Forward elimination of row i's right-hand side r in a symmetric tridiagonal system
    factored as L D L^T (``l`` = L[i+1, i]) whose rows lo..i-1 are eliminated already."""
    if i > lo:
        return r - l[i - 1] * rhs[i - 1]
    return r


@wp.func
def back_substitute(dinv: wp.array(dtype=wp.float64), l: wp.array(dtype=wp.float64),
                    rhs: wp.array(dtype=wp.float64), lo: int, hi: int):
    """Back substitution of the eliminated tridiagonal rows lo..hi-1 (``dinv`` = 1 / D):
    ``rhs`` becomes the solution."""
    for k in range(hi - lo):
        i = hi - 1 - k
        val = rhs[i] * dinv[i]
        if i + 1 < hi:
            val = val - l[i] * rhs[i + 1]
        rhs[i] = val
    return 0


@wp.func
def project_straight_twist(a: int, b: int, model: RodModel, state: RodState, spin: wp.array(dtype=wp.float64),
                           factors: RodFactors, dt: wp.float64, inv_dt: wp.float64, inv_dt2: wp.float64):
    for i in range(a + 1, b - 1):
        rj = -twist_residual(model, state, spin, factors, dt, i) - (
            model.twist_compliance[i] * inv_dt2 * factors.twist_lambda[i])
        factors.twist_rhs[i] = eliminated(rj, factors.twist_lower, factors.twist_rhs, i, a + 1)
    back_substitute(factors.twist_inv_pivot, factors.twist_lower, factors.twist_rhs, a + 1, b - 1)
    for i in range(a + 1, b - 1):
        dl = factors.twist_rhs[i]
        factors.twist_lambda[i] = factors.twist_lambda[i] + dl
        spin[i - 1] = spin[i - 1] - dl * inv_dt * model.inv_inertia[i - 1]
        spin[i] = spin[i] + dl * inv_dt * model.inv_inertia[i]
    return 0


@wp.func
def project_curved(a: int, b: int, model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d),
                   spin: wp.array(dtype=wp.float64), factors: RodFactors, dt: wp.float64, inv_dt: wp.float64,
                   inv_dt2: wp.float64):
    """One exact solve of a curved rod's coupled bending-twist system (block LDL^T factors)."""
    i0 = a + 1
    i1 = b - 1
    EI = model.bend_stiffness[model.vertex_rod[a]]
    for i in range(i0, i1):
        cm, c0, cp, wl = bend_coeffs(model.rest_length, i)
        g = factors.curved_coupling[i]
        kap = (state.x[i - 1] + v[i - 1] * dt) * cm + (state.x[i] + v[i] * dt) * c0 + (state.x[i + 1] + v[i + 1] * dt) * cp
        T = factors.bend_target[i] + g * ((spin[i - 1] + spin[i]) * dt)
        lam = factors.curved_lambda[i]
        ab = inv_dt2 / (EI * wl)
        cb = -(kap - T) - wp.vec3d(lam[0], lam[1], lam[2]) * ab
        ct = -twist_residual(model, state, spin, factors, dt, i) - model.twist_compliance[i] * inv_dt2 * lam[3]
        z = wp.vec4d(cb[0], cb[1], cb[2], ct)
        if i - 1 >= i0:
            z = z - factors.curved_lower1[i - 1] * factors.curved_rhs[i - 1]
        if i - 2 >= i0:
            z = z - factors.curved_lower2[i - 2] * factors.curved_rhs[i - 2]
        factors.curved_rhs[i] = z
    for k in range(i1 - i0):
        i = i1 - 1 - k
        y = factors.curved_inv_pivot[i] * factors.curved_rhs[i]
        if i + 1 < i1:
            y = y - wp.transpose(factors.curved_lower1[i]) * factors.curved_dlambda[i + 1]
        if i + 2 < i1:
            y = y - wp.transpose(factors.curved_lower2[i]) * factors.curved_dlambda[i + 2]
        factors.curved_dlambda[i] = y
    for i in range(i0, i1):
        cm, c0, cp, wl = bend_coeffs(model.rest_length, i)
        dl = factors.curved_dlambda[i]
        factors.curved_lambda[i] = factors.curved_lambda[i] + dl
        db = wp.vec3d(dl[0], dl[1], dl[2]) * inv_dt
        v[i - 1] = v[i - 1] + db * (cm * model.inv_mass[i - 1])
        v[i] = v[i] + db * (c0 * model.inv_mass[i])
        v[i + 1] = v[i + 1] + db * (cp * model.inv_mass[i + 1])
        # dC_b / dtheta = -g for both edges, dC_t / dtheta_{i-1, i} = -1, +1
        gb = wp.dot(factors.curved_coupling[i], db)
        spin[i - 1] = spin[i - 1] + (-gb - dl[3] * inv_dt) * model.inv_inertia[i - 1]
        spin[i] = spin[i] + (-gb + dl[3] * inv_dt) * model.inv_inertia[i]
    return 0


@wp.func
def project_stretch(a: int, b: int, model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d),
                    factors: RodFactors, dt: wp.float64, inv_dt: wp.float64, inv_dt2: wp.float64):
    """One exact XPBD (Newton) iteration on the edge lengths of the rod on vertices [a, b);
    returns the largest edge-length error (m) found before it."""
    worst = F0
    for j in range(a, b - 1):
        e = (state.x[j + 1] + v[j + 1] * dt) - (state.x[j] + v[j] * dt)
        cval = wp.length(e) - model.rest_length[j]
        worst = wp.max(worst, wp.abs(cval))
        rj = -cval - model.compliance[j] * inv_dt2 * factors.stretch_lambda[j]
        factors.stretch_rhs[j] = eliminated(rj, factors.stretch_lower, factors.stretch_rhs, j, a)
    back_substitute(factors.stretch_inv_pivot, factors.stretch_lower, factors.stretch_rhs, a, b - 1)
    for j in range(a, b - 1):
        dl = factors.stretch_rhs[j]
        factors.stretch_lambda[j] = factors.stretch_lambda[j] + dl
        imp = factors.stretch_dir[j] * (dl * inv_dt)
        c = model.cross_inv_mass[j]
        v[j] = v[j] - imp * (model.inv_mass[j] - c)
        v[j + 1] = v[j + 1] + imp * (model.inv_mass[j + 1] - c)
    return worst


@wp.func
def project_rod(r: int, model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d),
                spin: wp.array(dtype=wp.float64), factors: RodFactors, dt: wp.float64):
    """One exact XPBD (Newton) iteration on rod r's own constraints; returns the largest
    edge-length error (m) found before it.

    Bending (implicit bending only) and twist first, then the edge lengths, each block
    solved directly with the factors prepared for this step. Rigid rods are skipped: inside
    the sweeps they move as bodies (no bending, no twist, and no contact changes the length
    of their one edge), and :func:`project_rigid_length` sets their length after the sweeps.
    """
    if model.rigid[r] != 0:
        return F0
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    inv_dt = F1 / dt
    inv_dt2 = inv_dt * inv_dt
    if b - a >= 3:
        if model.curved[r] != 0:
            project_curved(a, b, model, state, v, spin, factors, dt, inv_dt, inv_dt2)
        else:
            if factors.implicit_bending != 0:
                project_straight_bending(r, a, b, model, state, v, factors, dt, inv_dt)
            project_straight_twist(a, b, model, state, spin, factors, dt, inv_dt, inv_dt2)
    return project_stretch(a, b, model, state, v, factors, dt, inv_dt, inv_dt2)


@wp.func
def project_rigid_length(r: int, model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d),
                         factors: RodFactors, dt: wp.float64, tolerance: wp.float64):
    """Rigid rod r's edge length after the sweeps (its velocities back at its vertices):
    Newton iterations on the one edge until its error is below ``tolerance`` (m; at most
    eight). Along the start-of-step axis the correction changes neither the centre-of-mass
    velocity nor the angular velocity, so it leaves every contact's velocity as the sweeps
    left it. Returns the error before the last iteration (m); 0 for elastic rods."""
    if model.rigid[r] == 0:
        return F0
    a = model.rod_start[r]
    inv_dt = F1 / dt
    err = F0
    for it in range(8):
        err = project_stretch(a, a + 2, model, state, v, factors, dt, inv_dt, inv_dt * inv_dt)
        if err < tolerance:
            break
    return err


@wp.kernel
def rod_projection(model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d), spin: wp.array(dtype=wp.float64),
                   factors: RodFactors, dt: wp.float64, residual: wp.array(dtype=wp.float64)):
    """One thread per rod: ``project_rod``. Rods share no vertex, so no races."""
    r = wp.tid()
    wp.atomic_max(residual, 0, project_rod(r, model, state, v, spin, factors, dt))


@wp.kernel
def rigid_length_projection(model: RodModel, state: RodState, v: wp.array(dtype=wp.vec3d), factors: RodFactors,
                            dt: wp.float64, tolerance: wp.float64, residual: wp.array(dtype=wp.float64)):
    """One thread per rod: ``project_rigid_length``."""
    wp.atomic_max(residual, 0, project_rigid_length(wp.tid(), model, state, v, factors, dt, tolerance))


# ----------------------------------------------------------------------------- energy, integration


@wp.kernel
def elastic_energy(model: RodModel, state: RodState, btarget: wp.array(dtype=wp.vec3d),
                   ref_twist: wp.array(dtype=wp.float64), body_accel: wp.vec3d, out: wp.array(dtype=wp.float64)):
    """Per rod: kinetic (translation and spin), potential (body force), bending, stretching
    and twist energy (J); ``btarget`` and ``ref_twist`` as computed by ``step_frames``."""
    r = wp.tid()
    a = model.rod_start[r]
    b = model.rod_start[r + 1]
    ek = F0
    ep = F0
    eb = F0
    es = F0
    et = F0
    EI = model.bend_stiffness[r]
    for i in range(a, b):
        ek = ek + HALF * model.mass[i] * wp.dot(state.v[i], state.v[i])
        ep = ep - model.mass[i] * wp.dot(body_accel, state.x[i])
    for j in range(a, b - 1):
        # consistent-mass cross term (rigid rods) and spin about the axis
        ek = ek + model.cross_mass[j] * wp.dot(state.v[j], state.v[j + 1])
        ek = ek + HALF * model.inertia[j] * state.spin[j] * state.spin[j]
        ep = ep - model.cross_mass[j] * wp.dot(body_accel, state.x[j] + state.x[j + 1])
        stretch = wp.length(state.x[j + 1] - state.x[j]) - model.rest_length[j]
        if model.compliance[j] > F0:
            es = es + HALF * stretch * stretch / model.compliance[j]
    for i in range(a + 1, b - 1):
        cm, c0, cp, wl = bend_coeffs(model.rest_length, i)
        kap = state.x[i - 1] * cm + state.x[i] * c0 + state.x[i + 1] * cp - btarget[i]
        eb = eb + HALF * EI * wl * wp.dot(kap, kap)
        tw = state.theta[i] - state.theta[i - 1] + ref_twist[i] - model.rest_twist[i]
        if model.twist_compliance[i] > F0:
            et = et + HALF * tw * tw / model.twist_compliance[i]
    wp.atomic_add(out, 0, ek)
    wp.atomic_add(out, 1, ep)
    wp.atomic_add(out, 2, eb)
    wp.atomic_add(out, 3, es)
    wp.atomic_add(out, 4, et)


@wp.kernel
def integrate_positions(x_in: wp.array(dtype=wp.vec3d), v: wp.array(dtype=wp.vec3d), dt: wp.float64,
                        x_out: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    x_out[i] = x_in[i] + v[i] * dt
