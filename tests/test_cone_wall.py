"""The cone wall (the inside of a hopper), added as a new wall kind in two files: the host's
distance agrees with the device's, a short rod settles where its vertex spheres touch the cone at
the heights geometry gives, and without the cone it falls through."""

import math
import pathlib
import subprocess

import numpy as np
import pytest
import warp as wp

from rodwarp.errors import RodwarpError
from rodwarp.kernels import walls as device_walls
from rodwarp.kernels.structs import Walls
from rodwarp.rodset import RodSet
from rodwarp.sim import STEEL, ModelBuilder, RodSolver, run
from rodwarp.sim.walls import KINDS, Cone, device_rows
from rodwarp.testing.scenes import straight_rod

G = 9.81
R = 0.005  # rod radius (m)
A = math.radians(30.0)  # half angle: sin A = 1/2, a sphere's centre rests 2 r above the apex
ROOT = pathlib.Path(__file__).resolve().parents[1]


@wp.kernel
def _surface(walls: Walls, x: wp.array(dtype=wp.vec3d), disp: wp.float64, dist: wp.array(dtype=wp.float64),
             normal: wp.array(dtype=wp.vec3d)):
    i = wp.tid()
    d, n = device_walls.wall_surface(walls, 0, x[i], disp)
    dist[i] = d
    normal[i] = n


def device_surface(wall, x, disp=0.0, direction=(0.0, 0.0, 1.0)):
    """The device's wall_surface of one wall at points x (n, 3): (distances, normals)."""
    rows = device_rows([wall], [True], np.asarray(direction, float))
    w = Walls()
    w.n = 1
    for name, a in rows.items():
        dtype = wp.vec4d if a.ndim == 2 else (wp.int32 if a.dtype == np.int32 else wp.float64)
        setattr(w, name, wp.array(a, dtype=dtype, device="cpu"))
    w.drive_dir = wp.vec3d(*direction)
    w.drive_disp = wp.float64(disp)
    w.drive_vel = wp.float64(0.0)
    xs = wp.array(np.asarray(x, float), dtype=wp.vec3d, device="cpu")
    d = wp.zeros(len(x), dtype=wp.float64, device="cpu")
    n = wp.zeros(len(x), dtype=wp.vec3d, device="cpu")
    wp.launch(_surface, dim=len(x), inputs=[w, xs, wp.float64(disp), d, n], device="cpu")
    return d.numpy(), n.numpy()


def test_host_and_device_distances_agree_and_the_normal_is_the_gradient():
    rng = np.random.default_rng(49)
    axis = rng.normal(size=3)
    cone = Cone.make((0.1, -0.2, 0.3), axis, math.radians(25.0), moving=True)
    x = cone.apex + rng.uniform(-0.5, 0.5, size=(200, 3))
    for disp in (0.0, 0.013):
        d, n = device_surface(cone, x, disp, direction=(0.0, 0.6, 0.8))
        assert np.abs(d - cone.distance(x, disp, (0.0, 0.6, 0.8))).max() < 1e-12
    d, n = device_surface(cone, x)
    assert np.abs(np.linalg.norm(n, axis=1) - 1.0).max() < 1e-12
    eps = 1e-6  # the normal is the distance's gradient (central differences, off the axis)
    grad = np.stack([(cone.distance(x + eps * e) - cone.distance(x - eps * e)) / (2 * eps)
                     for e in np.eye(3)], axis=1)
    assert np.abs(grad - n).max() < 1e-8
    # exactly on the axis (rho = 0) a sphere touches a whole circle: the normal is the axis
    upright = Cone.make((0.1, -0.2, 0.3), (0, 0, 1), math.radians(25.0))
    d0, n0 = device_surface(upright, [(0.1, -0.2, 0.7)])
    assert np.array_equal(n0[0], (0.0, 0.0, 1.0)) and d0[0] == pytest.approx(0.4 * math.sin(math.radians(25.0)))
    # the sign: inside positive, outside (and behind the apex) negative
    h = (x - cone.apex) @ cone.axis
    rho = np.linalg.norm(x - cone.apex - np.outer(h, cone.axis), axis=1)
    assert np.array_equal(d > 0, rho < h * math.tan(cone.half_angle))
    # exact where the nearest surface point is on a generator: a point inside at distance s from
    # a generator, and one outside it, measured directly
    s = 0.01
    u = np.cross(cone.axis, (1.0, 0.0, 0.0))
    u /= np.linalg.norm(u)  # a radial direction
    gen = math.cos(cone.half_angle) * cone.axis + math.sin(cone.half_angle) * u  # along the surface
    inward = math.sin(cone.half_angle) * cone.axis - math.cos(cone.half_angle) * u
    assert cone.distance(cone.apex + 0.4 * gen + s * inward) == pytest.approx(s, abs=1e-14)
    assert cone.distance(cone.apex + 0.4 * gen - s * inward) == pytest.approx(-s, abs=1e-14)


def test_cone_arguments_are_checked():
    with pytest.raises(RodwarpError, match="half_angle"):
        Cone.make((0, 0, 0), (0, 0, 1), 0.0)
    with pytest.raises(RodwarpError, match="half_angle"):
        Cone.make((0, 0, 0), (0, 0, 1), math.pi / 2)
    with pytest.raises(RodwarpError, match="axis"):
        Cone.make((0, 0, 0), (0, 0, 0), 0.5)
    c = Cone.make((0, 0, 0), (0, 0, 2), 0.5)
    assert c.kind == "cone" and c.name == "cone" and np.allclose(c.axis, (0, 0, 1))


def settle(polyline, remove_cone=False, duration=0.4):
    """A rigid rod dropped into an apex-down cone (apex at the origin, axis +z); final vertices."""
    rods = RodSet.from_polylines([polyline], R)
    builder = ModelBuilder(rods, STEEL, gravity=(0, 0, -G), mu=0.3, rod_model="rigid", device="cpu")
    builder.add_wall(Cone.make((0, 0, 0), (0, 0, 1), A, name="hopper"))
    model = builder.finalize()
    control, solver = model.control(), RodSolver(model)
    if remove_cone:
        control.remove_walls(["hopper"])
    state = run(solver, model.state(), duration, solver.default_dt(control), control=control)
    return model, solver, state.x.numpy()


def test_a_vertical_rod_on_the_axis_rests_on_its_lower_vertex_sphere_at_r_over_sin_a():
    h_rest = R / math.sin(A)  # a sphere of radius r in a cone of half angle A
    model, solver, x = settle(straight_rod((0.0, 0.0, h_rest + 0.01 + 2 * R), (0, 0, 1), 4 * R, R, n_vertices=2))
    low = x[np.argmin(x[:, 2])]
    # the overlap left is at most the post-stabilisation's tolerance (of a diameter); along the
    # axis an overlap s is a height s / sin A
    tol = solver.position_tolerance * 2 * R / math.sin(A)
    assert abs(low[2] - h_rest) <= tol, (low[2], h_rest, tol)
    assert np.abs(x[:, :2]).max() < 1e-12  # still on the axis
    assert abs(x[:, 2].max() - low[2] - 4 * R) < 1e-9  # still vertical and rigid


def test_a_rod_across_the_axis_rests_on_both_end_spheres_and_its_interior_stays_clear():
    L = 8 * R
    h_rest = (R + 0.5 * L * math.cos(A)) / math.sin(A)  # each end sphere touching the cone
    model, solver, x = settle(straight_rod((0.0, 0.0, h_rest + 0.01), (1, 0, 0), L, R, n_vertices=2))
    cone = model.walls[0]
    tol = solver.position_tolerance * 2 * R
    assert np.abs(cone.distance(x) - R).max() <= tol  # both end spheres on the cone
    assert abs(x[:, 2].mean() - h_rest) <= tol / math.sin(A)
    # the distance is concave: along the segment it is smallest at the ends, so the capsule's
    # interior, nearer the axis, is farther from the cone than its vertex spheres
    s = np.linspace(0.0, 1.0, 101)[:, None]
    d = cone.distance(x[0] + s * (x[1] - x[0]))
    assert d[1:-1].min() > min(d[0], d[-1])


def test_without_the_cone_the_rod_falls_through_the_apex():
    h_rest = R / math.sin(A)
    _, _, x = settle(straight_rod((0.0, 0.0, h_rest + 0.01 + 2 * R), (0, 0, 1), 4 * R, R, n_vertices=2),
                     remove_cone=True, duration=0.1)
    assert x[:, 2].min() < -0.02  # free fall past the apex: the test above can fail


def test_the_cone_lives_in_the_two_wall_modules():
    assert KINDS["cone"] == device_walls.CONE and hasattr(device_walls, "cone_surface")
    # its code names (the class, the device function and constant, the kind's tag), in the package
    code = subprocess.run(["git", "grep", "-l", "-E", r'\bCone\b|cone_surface|\bCONE\b|"cone"', "--", "rodwarp",
                           "kernels"], cwd=ROOT, capture_output=True, text=True)
    if code.returncode in (0, 1):  # a git checkout (1: no match, which would fail below)
        assert sorted(code.stdout.split()) == ["kernels/walls.py", "rodwarp/sim/walls.py"]
