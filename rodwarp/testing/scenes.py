"""Small validation scenes with analytic answers (cantilevers, inclines, stacks, crossings).

Validation material (:mod:`rodwarp.testing`): used by the tests, the benchmarks and users who
check the engine on their machine, not by rodwarp itself; each returns rods in metres.  The analytic answers they are checked against are
listed in ``docs/physics.md``.
"""

from __future__ import annotations

import math

import numpy as np

from rodwarp.rodset import RodSet

# The test material of the analytic checks (docs/physics.md): L = 1 m, r = 0.01 m, E = 1e9 Pa,
# rho = 1000 kg/m^3 (so E I = 7.854 N m^2 and rho A = 0.31416 kg/m).
TEST_LENGTH = 1.0
TEST_RADIUS = 0.01
TEST_YOUNG = 1e9
TEST_DENSITY = 1000.0


def cantilever(n_edges: int = 9, length: float = TEST_LENGTH, radius: float = TEST_RADIUS):
    """A horizontal rod along +x clamped at x = 0.

    The clamp holds two vertices fixed: the root at x = 0 and a ghost vertex just behind it
    (x = -1e-3 h) that fixes the tangent.  The ghost edge is short so that the root's
    Voronoi length is h / 2, the part of its cell inside the beam; a ghost at -h would make
    the beam effectively h / 2 longer (tip sag 1.24x too large at 9 edges).

    Returns
    -------
    rods : RodSet
    pinned : ndarray of int
        Indices of the clamped vertices.
    """
    h = length / n_edges
    xs = np.concatenate([[-1e-3 * h], np.arange(0, n_edges + 1) * h])
    pts = np.stack([xs, np.zeros_like(xs), np.zeros_like(xs)], axis=1)
    return RodSet.from_polylines([pts], radius), np.array([0, 1])


def cantilever_sag(length=TEST_LENGTH, radius=TEST_RADIUS, young=TEST_YOUNG, density=TEST_DENSITY, g=9.81):
    """Euler-Bernoulli tip deflection under self-weight, q L^4 / (8 E I) (m)."""
    A = math.pi * radius**2
    I = math.pi * radius**4 / 4
    return density * A * g * length**4 / (8 * young * I)


def cantilever_frequency(length=TEST_LENGTH, radius=TEST_RADIUS, young=TEST_YOUNG, density=TEST_DENSITY):
    """First bending frequency (1.8751^2 / 2 pi) sqrt(E I / (rho A L^4)) (Hz)."""
    A = math.pi * radius**2
    I = math.pi * radius**4 / 4
    return 1.8751040687**2 / (2 * math.pi) * math.sqrt(young * I / (density * A * length**4))


def straight_rod(center, direction, length, radius, n_vertices=10) -> np.ndarray:
    """Vertices of a straight rod.

    Parameters
    ----------
    center, direction : array_like, shape (3,)
        Midpoint (m) and axis (any length; normalised here).
    length : float
        Rod length (m).
    radius : float
        Unused here (the caller builds the rod set with it); kept so scenes read alike.
    n_vertices : int
        Vertices, evenly spaced from end to end.

    Returns
    -------
    ndarray, shape (n_vertices, 3)
        Vertex positions (m).
    """
    c = np.asarray(center, float)
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    s = np.linspace(-0.5, 0.5, n_vertices)[:, None] * length
    return c + s * d


def log_cabin(layers=4, rods_per_layer=2, length=1.0, radius=0.01, spacing=0.6, n_vertices=10) -> RodSet:
    """A crossed stack: layer k has parallel rods along x (k even) or y (k odd), each layer
    resting on the one below (touching, zero gap), the lowest layer touching z = 0."""
    polys = []
    for k in range(layers):
        z = radius + 2 * radius * k
        for j in range(rods_per_layer):
            off = (j - (rods_per_layer - 1) / 2) * spacing
            if k % 2 == 0:
                polys.append(straight_rod((0, off, z), (1, 0, 0), length, radius, n_vertices))
            else:
                polys.append(straight_rod((off, 0, z), (0, 1, 0), length, radius, n_vertices))
    return RodSet.from_polylines(polys, radius)


def tilted_gravity(g: float, theta_deg: float, downhill=(1.0, 0.0, 0.0)) -> np.ndarray:
    """Gravity of magnitude g tilted by theta from -z toward ``downhill``: the same as a
    floor inclined by theta (m/s^2)."""
    t = math.radians(theta_deg)
    d = np.asarray(downhill, float)
    d = d / np.linalg.norm(d)
    return g * (math.sin(t) * d - math.cos(t) * np.array([0.0, 0.0, 1.0]))


def straightened(points) -> np.ndarray:
    """A straight polyline along +x with the same edge lengths (a straight rest shape)."""
    pts = np.asarray(points, float)
    h = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    out = np.zeros_like(pts)
    out[1:, 0] = np.cumsum(h)
    return out


def leaning_rod(phi_deg: float, length: float = 1.0, radius: float = TEST_RADIUS, n_vertices: int = 10):
    """A rod leaning at ``phi_deg`` to the floor z = 0 against the wall x = 0 (the ladder
    problem): its end spheres touch both. Returns the rod set; the walls are the caller's."""
    phi = math.radians(phi_deg)
    bottom = np.array([length * math.cos(phi) + radius, 0.0, radius])
    top = np.array([radius, 0.0, length * math.sin(phi) + radius])
    return RodSet.from_polylines([np.linspace(bottom, top, n_vertices)], radius)


def ladder_min_angle(mu_floor: float, mu_wall: float) -> float:
    """Smallest angle to the floor (deg) at which a uniform ladder stands:
    tan(phi) = (1 - mu_f mu_w) / (2 mu_f)."""
    return math.degrees(math.atan2(1.0 - mu_floor * mu_wall, 2.0 * mu_floor))
