"""Walls as one tagged type: the device functions every stage asks a wall (distance, normal,
velocity), so that contacts, the post-stabilisation and the checks share them and a new kind of
wall is added here alone.

Kinds (``Walls.kind``; host side :mod:`rodwarp.sim.walls`):

* 0, a plane: the half-space {x : n . x >= offset}, n its unit normal into the allowed region.

A wall that moves follows the control's drive: it is displaced by ``drive_dir * d(t)``. A
capsule touches a plane first at a segment endpoint (the distance to a plane is affine along a
segment), so the vertex spheres are the contacts.
"""

import warp as wp

from rodwarp.kernels.structs import Walls

wp.set_module_options({"enable_backward": False})

F0 = wp.float64(0.0)

PLANE = wp.constant(0)


@wp.func
def plane_surface(walls: Walls, p: int, x: wp.vec3d, disp: wp.float64):
    """Plane: geom0 = (n, offset)."""
    g = walls.geom0[p]
    n = wp.vec3d(g[0], g[1], g[2])
    # the plane's offset first, then the distance: the same operations as before walls had kinds
    return wp.dot(n, x) - (g[3] + walls.shift[p] * disp), n


@wp.func
def wall_surface(walls: Walls, p: int, x: wp.vec3d, disp: wp.float64):
    """Signed distance (m) of point ``x`` from wall p's surface, positive on the allowed side,
    and the wall's unit normal there (into the allowed region), with the drive displaced by
    ``disp`` (m)."""
    return plane_surface(walls, p, x, disp)


@wp.func
def wall_velocity(walls: Walls, p: int):
    """Mean velocity of wall p over the step (m/s)."""
    if walls.moving[p] != 0:
        return walls.drive_dir * walls.drive_vel
    return wp.vec3d(F0, F0, F0)
