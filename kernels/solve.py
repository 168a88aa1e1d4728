"""Whole Gauss-Seidel solve of one step in a single launch (sequential devices).

On the CPU every launch runs its threads one after another, so the sweeps of
``RodSolver.step`` are plain sequential Gauss-Seidel; doing all of them inside one
single-thread kernel gives the same visiting order (rod contacts, walls, rods) without the
Python launch overhead of three launches per sweep, which dominates for small scenes.
"""

import warp as wp

from rodwarp.kernels.constants import F0
from rodwarp.kernels.elastics import project_rigid_length, project_rod
from rodwarp.kernels.friction import rigid_from_body, rigid_to_body, solve_rod_contact
from rodwarp.kernels.wall_contacts import solve_rod_walls
from rodwarp.kernels.structs import (ContactFrame, RodContacts, RodFactors, RodModel, RodState, StepParams,
                                     WallContacts, Walls)

wp.set_module_options({"enable_backward": False})


@wp.kernel
def gauss_seidel_sequential(model: RodModel, state: RodState, contacts: RodContacts,
                            frames: wp.array(dtype=ContactFrame), walls: Walls, wall_contacts: WallContacts,
                            factors: RodFactors, params: StepParams, v: wp.array(dtype=wp.vec3d),
                            spin: wp.array(dtype=wp.float64), out: wp.array(dtype=wp.float64)):
    """Launch with dim = 1. out = [contact residual (m/s), stretch residual (m), sweeps]; the
    sweeps and tolerances come in ``params``.

    Rigid rods move as bodies inside the sweeps (``rigid_to_body``) and get their length
    after them (``project_rigid_length``)."""
    cres = F0  # the square of the largest velocity change of a sweep (m^2/s^2)
    sres = F0
    used = int(0)
    na = wall_contacts.n_active[0]
    tolerance = params.tolerance
    length_tolerance = params.length_tolerance
    for r in range(model.n_rods):
        rigid_to_body(r, model, factors.tangent, v, spin, factors.axial)
    for it in range(params.iterations):
        cres = F0
        sres = F0
        for k in range(contacts.count):
            cres = wp.max(cres, solve_rod_contact(k, frames, contacts.impulse, contacts.normal, params, v, spin))
        for q in range(na):
            cres = wp.max(cres, solve_rod_walls(q, walls, params, wall_contacts, v, spin))
        for r in range(model.n_rods):
            sres = wp.max(sres, project_rod(r, model, state, v, spin, factors, params.dt))
        used = it + 1
        if tolerance > F0 and it % 2 == 1:
            if cres < tolerance * tolerance and sres < length_tolerance:
                break
    for r in range(model.n_rods):
        rigid_from_body(r, model, factors.tangent, v, spin, factors.axial)
        sres = wp.max(sres, project_rigid_length(r, model, state, v, factors, params.dt, length_tolerance))
    out[0] = wp.sqrt(cres)
    out[1] = sres
    out[2] = wp.float64(used)
