"""Whole Gauss-Seidel solve of one step in a single launch (sequential devices).

On the CPU every launch runs its threads one after another, so the sweeps of
``RodSolver.step`` are plain sequential Gauss-Seidel; doing all of them inside one
single-thread kernel gives the same visiting order (contacts, walls, rods) without the
Python launch overhead of three launches per sweep, which dominates for small scenes.
"""

import warp as wp

from rodwarp.kernels.elastics import project_rod
from rodwarp.kernels.friction import solve_rod_contact, solve_vertex_planes

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)


@wp.kernel
def gauss_seidel_sequential(
    iterations: int,
    tolerance: wp.float64,
    length_tolerance: wp.float64,
    dt: wp.float64,
    beta: wp.float64,
    max_push: wp.float64,
    inv_mass: wp.array(dtype=wp.float64),
    # rod-rod contacts
    n_contacts: int,
    seg: wp.array(dtype=wp.vec2i),
    seg_vertex: wp.array(dtype=wp.int32),
    st: wp.array(dtype=wp.vec2d),
    normal: wp.array(dtype=wp.vec3d),
    gap: wp.array(dtype=wp.float64),
    mu: wp.float64,
    impulse: wp.array(dtype=wp.vec3d),
    # walls
    n_active: wp.array(dtype=wp.int32),
    active: wp.array(dtype=wp.int32),
    plane_normal: wp.array(dtype=wp.vec3d),
    plane_vel: wp.array(dtype=wp.vec3d),
    plane_mu: wp.array(dtype=wp.float64),
    n_planes: int,
    plane_gap: wp.array(dtype=wp.float64),
    plane_impulse: wp.array(dtype=wp.vec3d),
    # rods
    n_rods: int,
    rod_start: wp.array(dtype=wp.int32),
    x: wp.array(dtype=wp.vec3d),
    rest_length: wp.array(dtype=wp.float64),
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
    out: wp.array(dtype=wp.float64),
):
    """Launch with dim = 1. out = [contact residual (m/s), stretch residual (m), sweeps]."""
    cres = F0
    sres = F0
    used = int(0)
    na = n_active[0]
    for it in range(iterations):
        cres = F0
        sres = F0
        for k in range(n_contacts):
            cres = wp.max(cres, solve_rod_contact(k, seg, seg_vertex, st, normal, gap, inv_mass, mu, dt, beta,
                                                  max_push, impulse, v))
        for q in range(na):
            cres = wp.max(cres, solve_vertex_planes(active[q], inv_mass, plane_normal, plane_vel, plane_mu, n_planes,
                                                    plane_gap, dt, beta, max_push, plane_impulse, v))
        for r in range(n_rods):
            sres = wp.max(sres, project_rod(r, rod_start, x, inv_mass, rest_length, dt, implicit_bending, bcoef,
                                            btarget, bdiag, boff1, boff2, blam, brhs, bdl, compliance, sdir, sdiag, soff, slam,
                                            srhs, v))
        used = it + 1
        if tolerance > F0 and it % 2 == 1:
            if cres < tolerance and sres < length_tolerance:
                break
    out[0] = cres
    out[1] = sres
    out[2] = wp.float64(used)
