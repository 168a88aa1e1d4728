"""Device-side bundles of the arrays the kernels read and write (``wp.struct``).

Grouped the way the host groups them: the static rod model (:class:`RodModel`), the
evolving rod state (:class:`RodState`), the walls of this step (:class:`Walls`), the rod-rod
contacts of this step (:class:`RodContacts`), the per-rod solver factors
(:class:`RodFactors`) and the scalars of one step (:class:`StepParams`).

Indexing conventions (one rod = vertices ``rod_start[r] .. rod_start[r+1]-1``):

* per vertex ``i``: positions, velocities, masses;
* per edge, stored at its first vertex ``i`` (edge ``i -> i+1``; the slot of a rod's last
  vertex is unused): rest length, stretch compliance, axial spin, material angle,
  reference director, axial moment of inertia, the cross term of the inverse mass;
* per interior vertex ``i`` (between edges ``i-1`` and ``i``): bending and twist data.

The inverse mass matrix is tridiagonal: ``inv_mass`` on the diagonal and
``cross_inv_mass[i]`` at (i, i+1). Elastic rods have lumped masses (cross terms 0); a rigid
rod is two vertices with the consistent mass of a rigid bar, which has non-zero cross terms
(:mod:`rodwarp.sim.model`).
"""

import warp as wp

#: a contact law's parameters, laid out by the law's own modules (kernels/exact.py, kernels/imc.py)
LawParams = wp.types.vector(length=8, dtype=wp.float64)


@wp.struct
class RodModel:
    n_rods: int
    n_vertices: int
    rod_start: wp.array(dtype=wp.int32)
    vertex_rod: wp.array(dtype=wp.int32)
    seg_vertex: wp.array(dtype=wp.int32)
    mass: wp.array(dtype=wp.float64)  # diagonal of M (kg)
    cross_mass: wp.array(dtype=wp.float64)  # M[i, i+1] at edge i (kg)
    inv_mass: wp.array(dtype=wp.float64)  # diagonal of M^-1 (1/kg); 0 for pinned vertices
    cross_inv_mass: wp.array(dtype=wp.float64)  # M^-1[i, i+1] at edge i (1/kg)
    rest_length: wp.array(dtype=wp.float64)  # edge (m)
    arc: wp.array(dtype=wp.float64)  # vertex: rest arc length from its rod's first vertex (m)
    compliance: wp.array(dtype=wp.float64)  # edge stretch compliance h / (E A) (m/N)
    bend_stiffness: wp.array(dtype=wp.float64)  # rod E I (N m^2)
    radius: wp.array(dtype=wp.float64)  # rod (m)
    inertia: wp.array(dtype=wp.float64)  # edge axial moment of inertia (kg m^2)
    inv_inertia: wp.array(dtype=wp.float64)  # edge; 0 where the twist is clamped
    twist_compliance: wp.array(dtype=wp.float64)  # interior vertex: l_i / (G J) (1/(N m))
    rest_twist: wp.array(dtype=wp.float64)  # interior vertex (rad)
    rest_kappa: wp.array(dtype=wp.vec2d)  # interior vertex: rest curvature in the material frame
    curved: wp.array(dtype=wp.int32)  # rod: 1 when its rest shape is curved
    rigid: wp.array(dtype=wp.int32)  # rod: 1 for a rigid (two-vertex) rod
    rod_inv_mass: wp.array(dtype=wp.float64)  # rod: 1 / m (0 when fixed)
    rod_inv_iperp: wp.array(dtype=wp.float64)  # rod: 1 / I_perp of a rigid rod (0 when fixed)


@wp.struct
class RodState:
    x: wp.array(dtype=wp.vec3d)  # vertex position (m)
    v: wp.array(dtype=wp.vec3d)  # vertex velocity (m/s)
    spin: wp.array(dtype=wp.float64)  # edge: angular velocity of the material about its tangent (rad/s)
    theta: wp.array(dtype=wp.float64)  # edge: material angle from the reference director (rad)
    director: wp.array(dtype=wp.vec3d)  # edge: reference director u (unit, normal to the edge)


@wp.struct
class Walls:
    """The walls of a step: static arrays per wall, the drive as scalars (no per-step copies).
    Device functions of every kind: kernels/walls.py."""

    n: int
    kind: wp.array(dtype=wp.int32)  # which kind of wall (rodwarp/sim/walls.py, KINDS)
    geom0: wp.array(dtype=wp.vec4d)  # the kind's geometry, as rodwarp/sim/walls.py packs it
    geom1: wp.array(dtype=wp.vec4d)
    moving: wp.array(dtype=wp.int32)  # 1: the wall follows the drive
    shift: wp.array(dtype=wp.float64)  # a moving plane's offset change per metre of drive (n . drive direction)
    mu: wp.array(dtype=wp.float64)
    on: wp.array(dtype=wp.int32)  # 0: removed (no contact)
    drive_dir: wp.vec3d  # unit direction of the drive
    drive_disp: wp.float64  # drive displacement at the start of the step (m)
    drive_vel: wp.float64  # mean drive speed over the step along drive_dir (m/s)


@wp.struct
class RodContacts:
    count: int
    seg: wp.array(dtype=wp.vec2i)  # segment pair (sa < sb)
    st: wp.array(dtype=wp.vec2d)  # parameters of the contact points on sa and sb
    normal: wp.array(dtype=wp.vec3d)  # unit, from sb toward sa
    gap: wp.array(dtype=wp.float64)  # surface gap at the start of the step (m)
    impulse: wp.array(dtype=wp.vec3d)  # accumulated impulse on sa (N s); -impulse on sb


@wp.struct
class ContactSide:
    """One rod's side of a contact: where the impulse acts and how the rod responds.

    Inside the Gauss-Seidel sweeps a rigid rod's velocity is held as a rigid body's, the
    centre-of-mass velocity in its first vertex's slot and the angular velocity (spin
    included) in its second (:func:`rodwarp.kernels.friction.rigid_to_body`), so a rigid side
    needs only its lever and its turn; an elastic side acts on the edge's two vertices and
    its spin.
    """

    i: int  # first vertex of the edge
    rigid: int
    s: wp.float64  # parameter on the edge
    q0: wp.float64  # elastic: velocity change of the edge's ends per unit impulse
    q1: wp.float64
    ispin: wp.float64  # elastic: inverse axial inertia of the edge
    im: wp.float64  # rigid: 1 / m
    lever: wp.vec3d  # rigid: from the centre of mass to the point; elastic: t x (surface offset), the spin's lever
    turn: wp.mat33d  # rigid: I^-1 [lever]x, the angular velocity change per unit impulse (1 / (kg m))


@wp.struct
class ContactFrame:
    """What a rod-rod contact's local problem needs that does not change within a step."""

    a: ContactSide
    b: ContactSide
    W: wp.mat33d  # mobility of the contact (both sides, m / (N s))
    e1: wp.vec3d  # tangent basis (e2 = n x e1)
    k: wp.vec4d  # (n W n, e1 W e1, e1 W e2, e2 W e2)
    coupled: int  # W couples the normal and tangential parts
    target: wp.float64  # lowest normal relative velocity (m/s)
    Winv: wp.mat33d  # W^-1 (N s / m), for the exact sticking impulse; zero when W is singular
    gamma: wp.float64  # the sliding solve's multiplier in the last sweep (m/s per N s), its next guess
    gap: wp.float64  # surface gap at the start of the step (m; negative: overlap), for laws acting at a distance (IMC)


@wp.struct
class WallContacts:
    gap: wp.array(dtype=wp.float64)  # vertex x wall; > 1e299 when out of reach
    normal: wp.array(dtype=wp.vec3d)  # vertex x wall: the wall's normal at the vertex, start of the step
    impulse: wp.array(dtype=wp.vec3d)  # vertex x wall (N s)
    active: wp.array(dtype=wp.int32)  # rods with a vertex within reach of a wall
    n_active: wp.array(dtype=wp.int32)
    span: wp.array(dtype=wp.vec2i)  # per active rod: its first frame and number of frames
    key: wp.array(dtype=wp.int32)  # per frame: its vertex x wall index
    frames: wp.array(dtype=ContactFrame)  # per in-reach contact, side ``a`` only (the wall has none)
    n_frames: wp.array(dtype=wp.int32)  # frames needed this step (may exceed the capacity)


@wp.struct
class RodFactors:
    """Per-step factors and multipliers of every rod's internal constraints.

    Each constraint family (bending, stretching, twist, curved rods' coupled bending and twist)
    keeps the LDL^T factors of its banded system (``*_inv_pivot`` = 1 / D, ``*_lower*`` the
    sub-diagonals of L), its multipliers (``*_lambda``) and a sweep's scratch (``*_rhs``,
    ``*_dlambda``)."""

    implicit_bending: int
    # straight rods: bending (scalar pentadiagonal, three right-hand sides)
    bend_stencil: wp.array(dtype=wp.vec4d)  # stencil (c-, c0, c+) and compliance / dt^2
    bend_target: wp.array(dtype=wp.vec3d)  # rest curvature vector in the current frame
    bend_inv_pivot: wp.array(dtype=wp.float64)  # LDL^T: 1 / D_i (reciprocals: the sweeps multiply, never divide)
    bend_lower1: wp.array(dtype=wp.float64)  # L[i+1, i]
    bend_lower2: wp.array(dtype=wp.float64)  # L[i+2, i]
    bend_lambda: wp.array(dtype=wp.vec3d)  # the step's accumulated multipliers
    bend_rhs: wp.array(dtype=wp.vec3d)  # a sweep's right-hand side (the constraint's residual)
    bend_dlambda: wp.array(dtype=wp.vec3d)  # a sweep's multiplier change (the solve's output)
    # stretching (tridiagonal per rod)
    stretch_dir: wp.array(dtype=wp.vec3d)  # edge direction at the start of the step (the constraint's gradient)
    stretch_inv_pivot: wp.array(dtype=wp.float64)  # LDL^T of the tridiagonal system: 1 / D_j
    stretch_lower: wp.array(dtype=wp.float64)  # L[j+1, j]
    stretch_lambda: wp.array(dtype=wp.float64)  # the step's accumulated multipliers
    stretch_rhs: wp.array(dtype=wp.float64)  # a sweep's right-hand side
    # rigid rods inside the sweeps: (v_1 - v_0) . t, the part of the ends' relative velocity
    # a rigid body's velocity does not hold (stretching, set by the length constraint alone)
    axial: wp.array(dtype=wp.float64)
    # twist (tridiagonal per rod, straight rods)
    tangent: wp.array(dtype=wp.vec3d)  # edge tangent at the start of the step
    ref_twist: wp.array(dtype=wp.float64)  # interior vertex: reference twist at the start of the step
    twist_inv_pivot: wp.array(dtype=wp.float64)  # 1 / D_i
    twist_lower: wp.array(dtype=wp.float64)  # L[i+1, i]
    twist_lambda: wp.array(dtype=wp.float64)  # the step's accumulated multipliers
    twist_rhs: wp.array(dtype=wp.float64)  # a sweep's right-hand side
    # curved rods: bending and twist as one block-pentadiagonal system of 4 x 4 blocks
    curved_coupling: wp.array(dtype=wp.vec3d)  # d(target) / d(theta) of each adjacent edge
    curved_pivot: wp.array(dtype=wp.mat44d)  # D_i
    curved_inv_pivot: wp.array(dtype=wp.mat44d)  # D_i^-1
    curved_lower1: wp.array(dtype=wp.mat44d)  # L[i+1, i]
    curved_lower2: wp.array(dtype=wp.mat44d)  # L[i+2, i]
    curved_lambda: wp.array(dtype=wp.vec4d)  # multipliers (bending xyz, twist)
    curved_rhs: wp.array(dtype=wp.vec4d)  # a sweep's right-hand side
    curved_dlambda: wp.array(dtype=wp.vec4d)  # a sweep's multiplier change


@wp.struct
class RawContacts:
    """The narrowphase's output, unsorted: up to ``capacity`` contact points, ``count[0]`` found
    (may exceed the capacity: the host grows the arrays and runs it again)."""

    seg: wp.array(dtype=wp.vec2i)  # segment pair (sa < sb)
    key: wp.array(dtype=wp.int64)  # sort key: 3 (sa nseg + sb), + 1 + end for a contact at a segment end
    st: wp.array(dtype=wp.vec2d)  # parameters of the contact points on sa and sb
    normal: wp.array(dtype=wp.vec3d)  # unit, from sb toward sa
    gap: wp.array(dtype=wp.float64)  # surface gap (m)
    capacity: int
    count: wp.array(dtype=wp.int32)


@wp.struct
class StepParams:
    dt: wp.float64
    mu: wp.float64  # rod-rod friction coefficient
    beta: wp.float64  # Baumgarte fraction of an overlap (beyond the slop) removed per step
    slop: wp.float64  # overlap left alone (m): no push, so a resting contact's problem repeats
    max_push: wp.float64  # largest separation speed an overlap may cause (m/s)
    contact_distance: wp.float64  # base speculative margin (m)
    warm: wp.float64  # fraction of last step's impulses reused
    relax: wp.float64  # over-relaxation of each contact's impulse update (1: plain Gauss-Seidel)
    iterations: int  # most Gauss-Seidel sweeps (the single-launch solve of a sequential device)
    tolerance: wp.float64  # stop sweeping below this velocity change (m/s); 0: never early
    length_tolerance: wp.float64  # ... and with no edge length off by more than this (m)
    law: int  # contact law: its tag (kernels/contact_laws.py; host rodwarp/sim/contact_law.py)
    law_params: LawParams  # the law's parameters, as its host module packs them (device_params)
    restitution: wp.float64  # Newton coefficient of restitution e of the exact law (0: perfectly inelastic, off)
    bounce_speed: wp.float64  # approach speed (m/s) a contact must exceed to bounce (resting contacts do not)
