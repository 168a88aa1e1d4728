"""Rod elastics: bending predictor and inextensibility (stretch) projection.

Bending
    Discrete isotropic bending energy of a polyline with rest edge lengths h_j,

        E_b = sum_i  (E I / (2 l_i)) |kappa_i|^2,
        kappa_i = (x_{i+1} - x_i) / h_i - (x_i - x_{i-1}) / h_{i-1},   l_i = (h_{i-1} + h_i) / 2,

    which equals the discrete-elastic-rod energy E I (2 tan(theta_i / 2))^2 / (2 l_i) to
    second order in the turning angle theta_i for inextensible edges.  It is quadratic in x
    with a constant pentadiagonal Hessian K (one copy per coordinate), so the implicit step
    (M + theta dt^2 K) v' = M v + dt (f - K x) costs one banded LDL^T solve per rod and is
    unconditionally stable for theta = 1, symplectic Euler for theta = 0.

Stretching
    Edge lengths are compliant constraints C_j = |x_{j+1} - x_j| - h_j with compliance
    h_j / (E A) (XPBD).  The constraints of one rod form a chain, so their system
    (J W J^T + alpha / dt^2) is tridiagonal and solved exactly per rod (Thomas algorithm),
    which removes the explicit axial limit dt < h / sqrt(E / rho) altogether.
"""

import warp as wp

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)
F1 = wp.float64(1.0)


@wp.func
def bend_coeffs(rest_length: wp.array(dtype=wp.float64), i: int):
    """Stencil (c_-1, c_0, c_+1) of kappa_i at interior vertex i and the weight 1 / l_i."""
    hm = rest_length[i - 1]
    hp = rest_length[i]
    cm = F1 / hm
    cp = F1 / hp
    return cm, -(cm + cp), cp, wp.float64(2.0) / (hm + hp)


@wp.kernel
def rest_curvature_targets(
    rod_start: wp.array(dtype=wp.int32),
    vertex_rod: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    rest_x: wp.array(dtype=wp.vec3d),
    rest_kappa: wp.array(dtype=wp.vec3d),
    target: wp.array(dtype=wp.vec3d),
):
    """Per vertex: the rest curvature vector rotated into the rod's current local frame.

    The frame is the rotation that best maps the rest window x_{i-2..i+2} onto the current
    one (polar decomposition of their cross-covariance), so a naturally curved rod keeps
    its shape, bend plane and torsion up to a rigid motion. Evaluated at the start of the
    step, it leaves each bending constraint linear in x (same matrix as for straight rods).
    """
    i = wp.tid()
    r = vertex_rod[i]
    a = rod_start[r]
    b = rod_start[r + 1]
    if i <= a or i >= b - 1:
        target[i] = wp.vec3d(F0, F0, F0)
        return
    j0 = wp.max(a, i - 2)
    j1 = wp.min(b - 1, i + 2)
    cx = wp.vec3d(F0, F0, F0)
    cr = wp.vec3d(F0, F0, F0)
    for j in range(j0, j1 + 1):
        cx = cx + x[j]
        cr = cr + rest_x[j]
    inv = F1 / wp.float64(j1 - j0 + 1)
    cx = cx * inv
    cr = cr * inv
    A = wp.mat33d()
    for j in range(j0, j1 + 1):
        A = A + wp.outer(x[j] - cx, rest_x[j] - cr)
    U = wp.mat33d()
    sig = wp.vec3d()
    V = wp.mat33d()
    wp.svd3(A, U, sig, V)
    R = U * wp.transpose(V)
    if wp.determinant(R) < F0:
        D = wp.mat33d(F1, F0, F0, F0, F1, F0, F0, F0, -F1)
        R = U * D * wp.transpose(V)
    target[i] = R * rest_kappa[i]


@wp.func
def pentadiagonal_factor(
    a: int,
    b: int,
    diag: wp.array(dtype=wp.float64),
    off1: wp.array(dtype=wp.float64),
    off2: wp.array(dtype=wp.float64),
):
    """In-place LDL^T of the SPD pentadiagonal matrix on rows [a, b).

    diag -> D, off1 (row i with i+1) -> L[i+1, i], off2 (row i with i+2) -> L[i+2, i].
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
    return 0


@wp.func
def pentadiagonal_substitute(
    a: int,
    b: int,
    diag: wp.array(dtype=wp.float64),
    off1: wp.array(dtype=wp.float64),
    off2: wp.array(dtype=wp.float64),
    rhs: wp.array(dtype=wp.vec3d),
    out: wp.array(dtype=wp.vec3d),
):
    """Solve with the factors of ``pentadiagonal_factor`` for three right-hand sides
    (rhs is overwritten by the forward substitution)."""
    for i in range(a, b):
        z = rhs[i]
        if i - 1 >= a:
            z = z - rhs[i - 1] * off1[i - 1]
        if i - 2 >= a:
            z = z - rhs[i - 2] * off2[i - 2]
        rhs[i] = z
    for k in range(b - a):
        i = b - 1 - k
        y = rhs[i] / diag[i]
        if i + 1 < b:
            y = y - out[i + 1] * off1[i]
        if i + 2 < b:
            y = y - out[i + 2] * off2[i]
        out[i] = y
    return 0


@wp.kernel
def velocity_predictor(
    rod_start: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    mass: wp.array(dtype=wp.float64),
    inv_mass: wp.array(dtype=wp.float64),
    rest_length: wp.array(dtype=wp.float64),
    bend_stiffness: wp.array(dtype=wp.float64),
    body_accel: wp.vec3d,
    damping: wp.float64,
    dt: wp.float64,
    explicit_bending: int,
    btarget: wp.array(dtype=wp.vec3d),
    v_out: wp.array(dtype=wp.vec3d),
):
    """One thread per rod: velocity after damping, body force and (explicit) bending.

    Damping first decays the old velocity, v / (1 + gamma dt), so that static forces, and
    the constraint forces that balance them, are not scaled by it.  Implicit bending is
    not applied here but as compliant constraints inside the Gauss-Seidel sweep
    (``bending_projection``), so that every block of the sweep uses the same mass metric and
    the fixed point of the step is the true static equilibrium.
    """
    r = wp.tid()
    a = rod_start[r]
    b = rod_start[r + 1]
    decay = F1 / (F1 + damping * dt)
    for i in range(a, b):
        if inv_mass[i] == F0:
            v_out[i] = v[i]
        else:
            v_out[i] = v[i] * decay + body_accel * dt
    if explicit_bending != 0 and b - a >= 3:
        EI = bend_stiffness[r]
        for i in range(a + 1, b - 1):
            cm, c0, cp, wl = bend_coeffs(rest_length, i)
            kap = x[i - 1] * cm + x[i] * c0 + x[i + 1] * cp - btarget[i]
            f = kap * (EI * wl * dt)
            v_out[i - 1] = v_out[i - 1] - f * (cm * inv_mass[i - 1])
            v_out[i] = v_out[i] - f * (c0 * inv_mass[i])
            v_out[i + 1] = v_out[i + 1] - f * (cp * inv_mass[i + 1])


@wp.kernel
def bending_factor(
    rod_start: wp.array(dtype=wp.int32),
    inv_mass: wp.array(dtype=wp.float64),
    rest_length: wp.array(dtype=wp.float64),
    bend_stiffness: wp.array(dtype=wp.float64),
    dt: wp.float64,
    bcoef: wp.array(dtype=wp.vec4d),
    bdiag: wp.array(dtype=wp.float64),
    boff1: wp.array(dtype=wp.float64),
    boff2: wp.array(dtype=wp.float64),
):
    """One thread per rod: factor J W J^T + alpha / dt^2 of the bending constraints.

    Also stores each constraint's stencil and alpha / dt^2 in ``bcoef`` so the iterations
    need no divisions.

    kappa_i is linear in x, so this matrix depends only on masses, rest lengths, E I and dt:
    it is factored once per step size and reused by every iteration of every step.
    """
    r = wp.tid()
    a = rod_start[r]
    b = rod_start[r + 1]
    if b - a < 3:
        return
    EI = bend_stiffness[r]
    inv_dt2 = F1 / (dt * dt)
    for i in range(a + 1, b - 1):
        cm, c0, cp, wl = bend_coeffs(rest_length, i)
        w0 = inv_mass[i]
        wq = inv_mass[i + 1]
        at = inv_dt2 / (EI * wl)
        bcoef[i] = wp.vec4d(cm, c0, cp, at)
        bdiag[i] = cm * cm * inv_mass[i - 1] + c0 * c0 * w0 + cp * cp * wq + at
        boff1[i] = F0
        boff2[i] = F0
        if i + 1 < b - 1:
            dm, d0, dp, wl1 = bend_coeffs(rest_length, i + 1)
            boff1[i] = c0 * dm * w0 + cp * d0 * wq
        if i + 2 < b - 1:
            em, e0, ep, wl2 = bend_coeffs(rest_length, i + 2)
            boff2[i] = cp * em * wq
    pentadiagonal_factor(a + 1, b - 1, bdiag, boff1, boff2)


@wp.kernel
def stretch_factor(
    rod_start: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    inv_mass: wp.array(dtype=wp.float64),
    compliance: wp.array(dtype=wp.float64),
    dt: wp.float64,
    sdir: wp.array(dtype=wp.vec3d),
    sdiag: wp.array(dtype=wp.float64),
    soff: wp.array(dtype=wp.float64),
):
    """One thread per rod, once per step: edge directions at the start of the step and the
    Thomas factors of J W J^T + alpha / dt^2 for the edge-length constraints.

    SHAKE: corrections act along the start-of-step edges (fixed during the step), which keeps
    the scheme symplectic (no energy drift) where PBD's current-edge choice dissipates, and
    makes the matrix constant within the step.
    """
    r = wp.tid()
    a = rod_start[r]
    b = rod_start[r + 1]
    inv_dt2 = F1 / (dt * dt)
    for j in range(a, b - 1):
        e0 = x[j + 1] - x[j]
        l0 = wp.length(e0)
        nj = wp.vec3d(F0, F0, F0)
        if l0 > F0:
            nj = e0 / l0
        sdir[j] = nj
    for j in range(a, b - 1):
        d = inv_mass[j] + inv_mass[j + 1] + compliance[j] * inv_dt2
        off = F0
        if j + 1 < b - 1:
            off = -inv_mass[j + 1] * wp.dot(sdir[j], sdir[j + 1])
        if d <= wp.float64(1.0e-300):
            # both ends pinned: a row that changes nothing
            d = F1
            off = F0
        if j > a:
            d = d - soff[j - 1] * soff[j - 1] / sdiag[j - 1]
        sdiag[j] = d
        soff[j] = off


@wp.func
def project_rod(
    r: int,
    rod_start: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    inv_mass: wp.array(dtype=wp.float64),
    rest_length: wp.array(dtype=wp.float64),
    dt: wp.float64,
    implicit_bending: int,
    bcoef: wp.array(dtype=wp.vec4d),
    btarget: wp.array(dtype=wp.vec3d),
    bdiag: wp.array(dtype=wp.float64),
    boff1: wp.array(dtype=wp.float64),
    boff2: wp.array(dtype=wp.float64),
    blam: wp.array(dtype=wp.vec3d),
    brhs: wp.array(dtype=wp.vec3d),
    bdl: wp.array(dtype=wp.vec3d),
    compliance: wp.array(dtype=wp.float64),
    sdir: wp.array(dtype=wp.vec3d),
    sdiag: wp.array(dtype=wp.float64),
    soff: wp.array(dtype=wp.float64),
    slam: wp.array(dtype=wp.float64),
    srhs: wp.array(dtype=wp.float64),
    v: wp.array(dtype=wp.vec3d),
):
    """One exact XPBD (Newton) iteration on rod r's own constraints; returns the largest
    edge-length error (m) found before it.

    First all bending constraints (implicit bending only), then all edge-length
    constraints, each block solved directly with the factors prepared for this step.  Works
    on the predicted positions x + dt v and changes v only, so contacts, bending and
    stretching share one velocity state and one mass metric inside the Gauss-Seidel sweep.
    """
    a = rod_start[r]
    b = rod_start[r + 1]
    inv_dt = F1 / dt
    inv_dt2 = inv_dt * inv_dt
    if implicit_bending != 0 and b - a >= 3:
        for i in range(a + 1, b - 1):
            c = bcoef[i]
            Cb = (x[i - 1] + v[i - 1] * dt) * c[0] + (x[i] + v[i] * dt) * c[1] + (x[i + 1] + v[i + 1] * dt) * c[2]
            brhs[i] = -(Cb - btarget[i]) - blam[i] * c[3]
        pentadiagonal_substitute(a + 1, b - 1, bdiag, boff1, boff2, brhs, bdl)
        for i in range(a + 1, b - 1):
            c = bcoef[i]
            dlb = bdl[i]
            blam[i] = blam[i] + dlb
            g = dlb * inv_dt
            v[i - 1] = v[i - 1] + g * (c[0] * inv_mass[i - 1])
            v[i] = v[i] + g * (c[1] * inv_mass[i])
            v[i + 1] = v[i + 1] + g * (c[2] * inv_mass[i + 1])

    worst = F0
    for j in range(a, b - 1):
        e = (x[j + 1] + v[j + 1] * dt) - (x[j] + v[j] * dt)
        cval = wp.length(e) - rest_length[j]
        worst = wp.max(worst, wp.abs(cval))
        rj = -cval - compliance[j] * inv_dt2 * slam[j]
        if j > a:
            rj = rj - soff[j - 1] / sdiag[j - 1] * srhs[j - 1]
        srhs[j] = rj
    for k in range(b - a - 1):
        j = b - 2 - k
        val = srhs[j]
        if j + 1 < b - 1:
            val = val - soff[j] * srhs[j + 1]
        srhs[j] = val / sdiag[j]
    for j in range(a, b - 1):
        dl = srhs[j]
        slam[j] = slam[j] + dl
        imp = sdir[j] * (dl * inv_dt)
        v[j] = v[j] - imp * inv_mass[j]
        v[j + 1] = v[j + 1] + imp * inv_mass[j + 1]
    return worst


@wp.kernel
def rod_projection(
    rod_start: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    inv_mass: wp.array(dtype=wp.float64),
    rest_length: wp.array(dtype=wp.float64),
    dt: wp.float64,
    implicit_bending: int,
    bcoef: wp.array(dtype=wp.vec4d),
    btarget: wp.array(dtype=wp.vec3d),
    bdiag: wp.array(dtype=wp.float64),
    boff1: wp.array(dtype=wp.float64),
    boff2: wp.array(dtype=wp.float64),
    blam: wp.array(dtype=wp.vec3d),
    brhs: wp.array(dtype=wp.vec3d),
    bdl: wp.array(dtype=wp.vec3d),
    compliance: wp.array(dtype=wp.float64),
    sdir: wp.array(dtype=wp.vec3d),
    sdiag: wp.array(dtype=wp.float64),
    soff: wp.array(dtype=wp.float64),
    slam: wp.array(dtype=wp.float64),
    srhs: wp.array(dtype=wp.float64),
    v: wp.array(dtype=wp.vec3d),
    residual: wp.array(dtype=wp.float64),
):
    """One thread per rod: ``project_rod``. Rods share no vertex, so no races."""
    r = wp.tid()
    worst = project_rod(r, rod_start, x, inv_mass, rest_length, dt, implicit_bending, bcoef, btarget, bdiag, boff1,
                        boff2,
                        blam, brhs, bdl, compliance, sdir, sdiag, soff, slam, srhs, v)
    wp.atomic_max(residual, 0, worst)


@wp.kernel
def elastic_energy(
    rod_start: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    mass: wp.array(dtype=wp.float64),
    rest_length: wp.array(dtype=wp.float64),
    compliance: wp.array(dtype=wp.float64),
    bend_stiffness: wp.array(dtype=wp.float64),
    btarget: wp.array(dtype=wp.vec3d),
    body_accel: wp.vec3d,
    out: wp.array(dtype=wp.float64),
):
    """Per rod: kinetic, potential (body force), bending and stretching energy (J)."""
    r = wp.tid()
    a = rod_start[r]
    b = rod_start[r + 1]
    ek = F0
    ep = F0
    eb = F0
    es = F0
    EI = bend_stiffness[r]
    half = wp.float64(0.5)
    for i in range(a, b):
        ek = ek + half * mass[i] * wp.dot(v[i], v[i])
        ep = ep - mass[i] * wp.dot(body_accel, x[i])
    for j in range(a, b - 1):
        stretch = wp.length(x[j + 1] - x[j]) - rest_length[j]
        if compliance[j] > F0:
            es = es + half * stretch * stretch / compliance[j]
    for i in range(a + 1, b - 1):
        cm, c0, cp, wl = bend_coeffs(rest_length, i)
        kap = x[i - 1] * cm + x[i] * c0 + x[i + 1] * cp - btarget[i]
        eb = eb + half * EI * wl * wp.dot(kap, kap)
    wp.atomic_add(out, 0, ek)
    wp.atomic_add(out, 1, ep)
    wp.atomic_add(out, 2, eb)
    wp.atomic_add(out, 3, es)


@wp.kernel
def integrate_positions(
    x_in: wp.array(dtype=wp.vec3d),
    v: wp.array(dtype=wp.vec3d),
    dt: wp.float64,
    x_out: wp.array(dtype=wp.vec3d),
):
    i = wp.tid()
    x_out[i] = x_in[i] + v[i] * dt
