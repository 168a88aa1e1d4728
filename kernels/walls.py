"""Walls as one tagged type: the device functions every stage asks a wall (distance, normal,
velocity), so that contacts, the post-stabilisation and the checks share them and a new kind of
wall is added here alone.

Kinds (``Walls.kind``; host side :mod:`rodwarp.sim.walls`):

* 0, a plane: the half-space {x : n . x >= offset}, n its unit normal into the allowed region;
* 1, a cylinder with the rods inside it: {x : |(x - c) - a ((x - c) . a)| <= R}, axis through c
  along the unit a, radius R; its normal at a point is the inward radial direction there;
* 2, a cone with the rods inside it: {x : rho <= h tan(A)}, h = (x - p) . a the height above the
  apex p along the unit a (the opening direction), rho the distance from the axis, A the half
  angle; distance h sin(A) - rho cos(A), normal sin(A) a - cos(A) rho_hat (along a on the axis,
  where a sphere touches a whole circle). The distance's sign is right everywhere; its size is
  exact except behind the apex (h cos(A) + rho sin(A) < 0, outside the cone: there the nearest
  surface point is the apex and the value understates the distance).

A wall that moves follows the control's drive: its offset (plane) or axis point (cylinder) is
displaced by ``drive_dir * d(t)``; a cone's apex likewise. A capsule touches any kind first at a
segment endpoint (the distance to a plane is affine along a segment, the distance from an axis
convex, so R - rho and h sin(A) - rho cos(A) are concave and smallest at an endpoint), so the
vertex spheres are the contacts.
"""

import warp as wp

from rodwarp.kernels.constants import F0
from rodwarp.kernels.narrowphase import any_perpendicular
from rodwarp.kernels.structs import Walls

wp.set_module_options({"enable_backward": False})


PLANE = wp.constant(0)
CYLINDER = wp.constant(1)
CONE = wp.constant(2)


@wp.func
def plane_surface(walls: Walls, p: int, x: wp.vec3d, disp: wp.float64):
    """Plane: geom0 = (n, offset)."""
    g = walls.geom0[p]
    n = wp.vec3d(g[0], g[1], g[2])
    # the plane's offset first, then the distance: this order of operations is part of the results
    return wp.dot(n, x) - (g[3] + walls.shift[p] * disp), n


@wp.func
def cylinder_surface(walls: Walls, p: int, x: wp.vec3d, disp: wp.float64):
    """Cylinder, rods inside: geom0 = (a point of the axis, radius), geom1 = (unit axis, 0)."""
    g = walls.geom0[p]
    h = walls.geom1[p]
    c = wp.vec3d(g[0], g[1], g[2])
    if walls.moving[p] != 0:
        c = c + walls.drive_dir * disp
    a = wp.vec3d(h[0], h[1], h[2])
    rel = x - c
    rho = rel - a * wp.dot(rel, a)
    L = wp.length(rho)
    n = any_perpendicular(a)
    if L > F0:
        n = -rho / L
    return g[3] - L, n


@wp.func
def cone_surface(walls: Walls, p: int, x: wp.vec3d, disp: wp.float64):
    """Cone, rods inside: geom0 = (apex, sin A), geom1 = (unit axis toward the opening, cos A)."""
    g = walls.geom0[p]
    h = walls.geom1[p]
    c = wp.vec3d(g[0], g[1], g[2])
    if walls.moving[p] != 0:
        c = c + walls.drive_dir * disp
    a = wp.vec3d(h[0], h[1], h[2])
    rel = x - c
    z = wp.dot(rel, a)
    rho = rel - a * z
    L = wp.length(rho)
    n = a
    if L > F0:
        n = a * g[3] - rho * (h[3] / L)
    return z * g[3] - L * h[3], n


@wp.func
def wall_surface(walls: Walls, p: int, x: wp.vec3d, disp: wp.float64):
    """Signed distance (m) of point ``x`` from wall p's surface, positive on the allowed side,
    and the wall's unit normal there (into the allowed region), with the drive displaced by
    ``disp`` (m)."""
    if walls.kind[p] == CYLINDER:
        return cylinder_surface(walls, p, x, disp)
    if walls.kind[p] == CONE:
        return cone_surface(walls, p, x, disp)
    return plane_surface(walls, p, x, disp)


@wp.func
def wall_velocity(walls: Walls, p: int):
    """Mean velocity of wall p over the step (m/s)."""
    if walls.moving[p] != 0:
        return walls.drive_dir * walls.drive_vel
    return wp.vec3d(F0, F0, F0)
