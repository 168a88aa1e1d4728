"""The static description of a rod scene: :class:`Material`, walls (:mod:`rodwarp.sim.walls`), :class:`Model`.

Follows the Model / State / Control / solver split of Warp's simulation examples and of
Newton: the model holds what does not change during a run (masses, inertias, rest shape,
stiffness, the walls a scene can have); a :class:`~rodwarp.sim.state.State` holds what
evolves; a :class:`~rodwarp.sim.control.Control` holds the time-varying inputs (which walls
are in place, the container drive, applied torques); a solver advances ``state_in`` to
``state_out`` under a control.

Two rod models (``rod_model``):

``"elastic"``
    Polylines of any number of vertices with lumped masses, bending, stretching and twist
    (discrete elastic rods), and a spin degree of freedom per edge.
``"rigid"``
    Each (straight) rod is one rigid capsule: two vertices joined by an inextensible edge,
    with the *consistent* mass matrix of a rigid bar, M = [[a, b], [b, a]] (a + b = m / 2,
    a - b = 2 I_perp / l^2), which gives the exact translational mass m and transverse
    inertia I_perp = m (l^2 / 12 + r^2 / 4) of a solid cylinder, plus the spin about the
    axis with I = m r^2 / 2. About 5x cheaper than ten elastic vertices per rod.

All quantities are SI (m, kg, s, N, Pa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import warp as wp

from rodwarp import _warp
from rodwarp.errors import RodwarpError, RodwarpTypeError
from rodwarp.rodset import RodSet
from rodwarp.arguments import instance, real
from rodwarp.sim._limits import (DENSITY_RANGE, MAX_LENGTH_M, YOUNG_RANGE, check_model_options, check_rods, friction,
                                 pinned_indices)
from rodwarp.sim.contact_law import ContactLaw  # the registry, with its built-in laws
from rodwarp.sim.walls import Plane

if TYPE_CHECKING:
    from rodwarp.sim.state import State

ROD_MODELS = ("elastic", "rigid")


@dataclass(frozen=True)
class Material:
    """Isotropic elastic material.

    Parameters
    ----------
    young : float
        Young's modulus E (Pa), in ``YOUNG_RANGE`` (1 Pa to 1e13 Pa).
    density : float
        Mass density rho (kg/m^3), in ``DENSITY_RANGE`` (1e-2 to 1e5 kg/m^3).
    poisson : float
        Poisson ratio nu in (-1, 0.5); sets the shear modulus G = E / (2 (1 + nu)) of twist.
    """

    young: float = 200e9
    density: float = 7850.0
    poisson: float = 0.3

    def __post_init__(self):
        real("young", self.young, ge=YOUNG_RANGE[0], le=YOUNG_RANGE[1], unit="Pa",
             hint="Young's modulus; steel is 2e11 Pa (--young 2e11)")
        real("density", self.density, ge=DENSITY_RANGE[0], le=DENSITY_RANGE[1], unit="kg/m^3",
             hint="steel is 7850 kg/m^3 (--density 7850)")
        real("poisson", self.poisson, gt=-1.0, lt=0.5, hint="the Poisson ratio; steel's is 0.3")

    @property
    def shear(self) -> float:
        """Shear modulus G (Pa)."""
        return self.young / (2.0 * (1.0 + self.poisson))

    @property
    def wave_speed(self) -> float:
        """Axial wave speed sqrt(E / rho) (m/s)."""
        return math.sqrt(self.young / self.density)


STEEL = Material()


# ----------------------------------------------------------------------------- frames (host)


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _any_perpendicular(t):
    axis = np.eye(3)[int(np.argmin(np.abs(t)))]
    return _unit(np.cross(t, axis))


def _transport(u, t0, t1):
    """u carried by the smallest rotation taking unit t0 to unit t1 (rows)."""
    b = np.cross(t0, t1)
    c = np.sum(t0 * t1, axis=-1, keepdims=True)
    return u * c + np.cross(b, u) + b * (np.sum(b * u, axis=-1, keepdims=True) / (1.0 + c))


def _space_parallel_directors(x, offsets=None):
    """Tangents and directors of every edge by space-parallel transport along each rod from an
    arbitrary first director (the Bishop frame); rows at the edge's first vertex, the slot of
    a rod's last vertex repeats its last edge. Vectorised over rods (loop over edge rank)."""
    x = np.asarray(x, float)
    if offsets is None:
        offsets = np.array([0, len(x)])
    V = len(x)
    t = np.zeros((V, 3))
    t[:-1] = np.diff(x, axis=0)
    starts = np.asarray(offsets[:-1])
    n_edges = np.diff(offsets) - 1
    ok = np.ones(V, bool)
    ok[np.asarray(offsets[1:]) - 1] = False
    t[ok] = _unit(t[ok])
    u = np.zeros((V, 3))
    u[starts] = np.stack([_any_perpendicular(t[i]) for i in starts]) if len(starts) else u[starts]
    for j in range(1, int(n_edges.max(initial=0))):
        rows = starts[n_edges > j] + j
        w = _transport(u[rows - 1], t[rows - 1], t[rows])
        w -= t[rows] * np.sum(w * t[rows], axis=1, keepdims=True)
        u[rows] = _unit(w)
    last = np.asarray(offsets[1:]) - 1
    t[last] = t[last - 1]
    u[last] = u[last - 1]
    return t, u


def _window_rotation(x, rest, j):
    """Rotation that best maps the rest window around edge j onto the current one (Kabsch)."""
    lo, hi = max(0, j - 1), min(len(x), j + 3)
    A = (x[lo:hi] - x[lo:hi].mean(0)).T @ (rest[lo:hi] - rest[lo:hi].mean(0))
    U, _, Vt = np.linalg.svd(A)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def _vertex_frame(t, d1):
    """Bisector b, first and second directors of the vertex frames between consecutive edges."""
    b = _unit(t[:-1] + t[1:])
    m1 = _transport(d1[:-1], t[:-1], b) + _transport(d1[1:], t[1:], b)
    m1 -= b * np.sum(m1 * b, axis=-1, keepdims=True)
    m1 = _unit(m1)
    return b, m1, np.cross(b, m1)


class Model:
    """Static parameters of a rod scene, allocated on a Warp device.

    Parameters
    ----------
    rods : RodSet
        Rods in metres (converted when given in mm or um). The rest shape is
        ``rods.rest_points`` when present, else the initial polylines.
    material : Material
        Elastic material of every rod (steel by default).
    gravity : (3,) float
        Body acceleration (m/s^2), of magnitude at most ``MAX_GRAVITY`` (1e5 m/s^2); the
        default is Earth gravity along -z.
    mu : float
        Rod-rod friction coefficient, in [0, ``MAX_MU``] (10).
    damping : float
        Viscous damping rate gamma (1/s) on every vertex velocity and edge spin, in [0,
        ``MAX_DAMPING``] (1e6 1/s). Off by default.
    pinned : array of int, optional
        Input vertex indices held fixed (infinite mass); an edge with both ends pinned is
        clamped in twist too. With ``rod_model="rigid"`` a rod with any pinned vertex is fixed.
    contact_distance : float, optional
        Surface gap below which two rods count as touching (m), in [0, 1e6 m]; default d_min / 10.
    rod_contacts : bool
        Detect rod-rod contacts (off for single-rod validation scenes).
    extensible : bool
        Give edges the axial compliance h / (E A). Off by default: for stiff rods the
        axial strain is ~1e-8 and axial waves (kHz) are not resolved by the step, so exact
        inextensibility is the cheaper model and, unlike implicitly damped stretching, it
        conserves energy. Turn on to measure axial deformation.
    rod_model : {"elastic", "rigid"}
        See the module docstring; ``"rigid"`` needs straight rods.
    rolling : bool
        Let rods spin about their axes (friction at the surface rolls them). False locks the
        spin (an infinite axial inertia): friction then acts on the centreline only, the
        model of the seed paper's disMech, kept for comparison (docs/physics.md, "Coulomb
        friction at the surface, and rolling").
    contact_law : ContactLaw or str
        The law at rod-rod and rod-wall contacts (:class:`~rodwarp.sim.ContactLaw`, or the
        name of a registered one, :data:`~rodwarp.sim.contact_law.CONTACT_LAWS`): exact
        (default) or DisMech's IMC; its defaults (IMC's delta, stiffness) are filled in from
        the rods and gravity (``model.contact_law``). IMC acts on the centreline in DisMech: pair
        it with ``rolling=False``.
    device : str
        ``cpu``, ``cuda``, ``cuda:N`` or ``auto``.
    walls : sequence of walls
        Every wall the scene can have (:mod:`rodwarp.sim.walls`); a wall without a friction
        coefficient takes ``mu``. Usually given by :class:`~rodwarp.sim.builder.ModelBuilder`.
    box : (2, 3) float, optional
        Container corners (m) that size the broadphase's hash grid; default ``rods.box``.

    A model does not change once built: build the scene with
    :class:`~rodwarp.sim.builder.ModelBuilder` and call its ``finalize()``. The rods' radii must
    lie in [1 nm, 1000 km] and their coordinates within 1000 km of the origin
    (:mod:`rodwarp.sim._limits`).

    Raises
    ------
    TypeError
        An argument of the wrong kind (``rods`` not a RodSet, ``gravity`` not 3 numbers, ...).
    RodwarpError
        A value out of its range; the message names the argument, its range and unit.
    """

    def __init__(
        self,
        rods: RodSet,
        material: Material = STEEL,
        *,
        gravity=(0.0, 0.0, -9.81),
        mu: float = 0.2,
        damping: float = 0.0,
        pinned=None,
        contact_distance: float | None = None,
        rod_contacts: bool = True,
        extensible: bool = False,
        rod_model: str = "elastic",
        rolling: bool = True,
        contact_law: ContactLaw | str = "exact",
        device: str = "cpu",
        walls=(),
        box=None,
    ):
        rods = check_rods(rods)
        instance("material", material, Material, "a Material (Material(young=..., density=...))")
        instance("contact_law", contact_law, (ContactLaw, str), "a ContactLaw or the name of one ('exact', 'imc')")
        check_model_options(dict(gravity=gravity, mu=mu, damping=damping, pinned=pinned,
                                 contact_distance=contact_distance, rod_model=rod_model, device=device))
        if rod_model not in ROD_MODELS:
            raise RodwarpError(f"rod_model must be 'elastic' or 'rigid', got '{rod_model}'")
        _warp.init()
        self.rod_model = rod_model
        self.rolling = bool(rolling)
        self.material = material
        self.gravity = np.asarray(gravity, dtype=np.float64).reshape(3)
        self.mu = float(mu)
        self.damping = float(damping)
        self.device = _warp.resolve_device(device)
        self.rod_contacts = bool(rod_contacts)
        self.walls = self._checked_walls(walls)
        if box is None and rods.box is not None:
            box = rods.box
        self.box: np.ndarray | None = None if box is None else checked_box(box)
        pin_in = np.zeros(rods.n_vertices, dtype=bool)
        if pinned is not None:
            pin_in[pinned_indices(pinned, rods.n_vertices)] = True
        if rod_model == "rigid":
            rods, pin_in = self._as_rigid(rods, pin_in)
        self.rods = rods
        self.pinned = pin_in

        self._precompute(rods, material, pin_in, extensible, rod_model, rolling)
        self._resolve_contact(contact_distance, contact_law)
        self._allocate()

    # ------------------------------------------------------------------ precomputation (once, at finalize)
    def _precompute(self, rods: RodSet, material: Material, pin_in: np.ndarray, extensible: bool, rod_model: str,
                    rolling: bool) -> None:
        """Host arrays of the rods (the ``*_np`` attributes): edges, masses, inertias,
        compliances, rest curvatures and directors."""
        N, V = rods.n_rods, rods.n_vertices
        offsets = rods.offsets.astype(np.int64)
        rest = rods.rest_points if rods.rest_points is not None else rods.points
        rest_length, first, last = _edges(rest, offsets, V)
        vertex_rod = np.repeat(np.arange(N), np.diff(offsets))
        r = rods.radii
        area = math.pi * r**2
        inertia_area = math.pi * r**4 / 4.0
        edge_mass = rest_length * area[vertex_rod] * material.density  # 0 in the last-vertex slots
        if rod_model == "rigid":
            mass, cross_mass, inv_mass, cross_inv = _rigid_masses(edge_mass, rest_length, r, offsets, pin_in, V)
        else:
            mass, cross_mass, inv_mass, cross_inv = _lumped_masses(edge_mass, pin_in, V)
        compliance = np.where(last | (not extensible), 0.0, rest_length / (material.young * area[vertex_rod]))
        inertia = 0.5 * edge_mass * r[vertex_rod] ** 2
        clamped = last | (pin_in & np.roll(pin_in, -1)) | (not rolling)
        inv_inertia = np.where(clamped | (inertia <= 0), 0.0, 1.0 / np.where(inertia > 0, inertia, 1.0))
        # twist between edges i-1 and i at interior vertex i: l_i / (G J), J = pi r^4 / 2
        interior = ~first & ~last
        l_int = np.zeros(V)
        l_int[1:] = 0.5 * (rest_length[:-1] + rest_length[1:])
        twist_compliance = np.where(interior, l_int / (material.shear * 2.0 * inertia_area[vertex_rod]), 0.0)
        rest_kappa, curved, director = _rest_frames(rods.points, rest, offsets, interior, vertex_rod, N, V)

        self.curved = bool(curved.any())
        self.curved_rods_np = curved
        self.rest_kappa_np = rest_kappa
        self.director0_np = director
        self.n_rods, self.n_vertices = N, V
        self.offsets_np = offsets
        self.seg_vertex_np = np.flatnonzero(~last).astype(np.int32)
        self.n_segments = int(self.seg_vertex_np.size)
        self.mass_np = mass
        self.cross_mass_np = cross_mass
        self.inv_mass_np = inv_mass
        self.cross_inv_mass_np = cross_inv
        self.inertia_np = inertia
        self.inv_inertia_np = inv_inertia
        self.rest_length_np = rest_length
        self.vertex_rod_np = vertex_rod.astype(np.int32)
        self.bend_stiffness_np = material.young * inertia_area
        self.radius_np = r.astype(np.float64)
        self.compliance_np = compliance
        self.twist_compliance_np = twist_compliance
        self.edge_mass_np = edge_mass

    def _resolve_contact(self, contact_distance, contact_law) -> None:
        """The contact distance (m) and the contact law with its defaults filled in."""
        r = self.rods.radii
        self.contact_distance = float(contact_distance) if contact_distance is not None else 0.1 * float(2 * r.min())
        law = ContactLaw.from_tag(contact_law) if isinstance(contact_law, str) else contact_law
        g_mag = float(np.linalg.norm(self.gravity)) or 9.81
        rod_mass = (np.bincount(self.vertex_rod_np, weights=self.edge_mass_np, minlength=self.n_rods)
                    if self.n_vertices else np.zeros(1))
        self.contact_law = law.resolved(float(2 * r.min()), float(rod_mass.max()) * g_mag)
        # contacts must be found wherever the law acts
        self.contact_distance = max(self.contact_distance, self.contact_law.reach())

    def _allocate(self) -> None:
        """The device bundle of the model (:class:`~rodwarp.kernels.structs.RodModel`, ``arrays``)."""
        N, V = self.n_rods, self.n_vertices
        offsets = self.offsets_np
        rest_length = self.rest_length_np
        vertex_rod = self.vertex_rod_np
        r = self.rods.radii
        pin_in = self.pinned
        d = self.device
        st = self.arrays = _structs().RodModel()
        st.n_rods = N
        st.n_vertices = V
        st.rod_start = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=d)
        st.vertex_rod = wp.array(self.vertex_rod_np, dtype=wp.int32, device=d)
        st.seg_vertex = wp.array(self.seg_vertex_np, dtype=wp.int32, device=d)
        f64 = lambda a: wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=wp.float64, device=d)  # noqa: E731
        st.mass = f64(self.mass_np)
        st.cross_mass = f64(self.cross_mass_np)
        st.inv_mass = f64(self.inv_mass_np)
        st.cross_inv_mass = f64(self.cross_inv_mass_np)
        st.rest_length = f64(rest_length)
        cum = np.concatenate([[0.0], np.cumsum(rest_length)])[:-1]
        st.arc = f64(cum - cum[offsets[:-1]][vertex_rod] if V else cum)
        st.compliance = f64(self.compliance_np)
        st.bend_stiffness = f64(self.bend_stiffness_np)
        st.radius = f64(self.radius_np)
        st.inertia = f64(self.inertia_np)
        st.inv_inertia = f64(self.inv_inertia_np)
        st.twist_compliance = f64(self.twist_compliance_np)
        st.rest_twist = f64(np.zeros(V))
        st.rest_kappa = wp.array(self.rest_kappa_np, dtype=wp.vec2d, device=d)
        st.curved = wp.array(self.curved_rods_np, dtype=wp.int32, device=d)
        rigid = np.full(N, 1 if self.rod_model == "rigid" else 0, dtype=np.int32)
        st.rigid = wp.array(rigid, dtype=wp.int32, device=d)
        rod_mass = self.rod_masses()
        fixed = np.logical_or.reduceat(pin_in, offsets[:-1]) if N else np.zeros(0, bool)
        st.rod_inv_mass = f64(np.where(fixed, 0.0, 1.0 / rod_mass))
        if self.rod_model == "rigid":
            Lr = rest_length[offsets[:-1]]
            iperp = rod_mass * (Lr**2 / 12.0 + r**2 / 4.0)
            st.rod_inv_iperp = f64(np.where(fixed, 0.0, 1.0 / iperp))
        else:
            st.rod_inv_iperp = f64(np.zeros(N))

    def _checked_walls(self, walls) -> tuple:
        """The walls as the model keeps them (a tuple: fixed), each with a friction coefficient."""
        out, names = [], set()
        for w in walls:
            if w.name in names:
                raise RodwarpError(f"the model already has a wall named '{w.name}'; give another name")
            names.add(w.name)
            if w.mu is None:
                w.mu = self.mu
            else:
                friction(f"mu of wall '{w.name}'", w.mu)
            out.append(w)
        return tuple(out)

    @staticmethod
    def _as_rigid(rods: RodSet, pinned: np.ndarray):
        """Two-vertex rods (the end points) of straight input rods; refuses curved ones."""
        off = rods.offsets
        a, b = off[:-1], off[1:] - 1
        for name, pts in (("shape", rods.points), ("rest shape", rods.rest_points)):
            if pts is None:
                continue
            p0, p1 = pts[a], pts[b]
            chord = p1 - p0
            L = np.linalg.norm(chord, axis=1)
            rid = np.repeat(np.arange(rods.n_rods), np.diff(off))
            rel = pts - p0[rid]
            dev = np.linalg.norm(np.cross(rel, chord[rid]), axis=1) / L[rid]
            worst = np.zeros(rods.n_rods)
            np.maximum.at(worst, rid, dev)
            bad = np.flatnonzero(worst > 1e-3 * rods.radii)
            if bad.size:
                k = int(bad[0])
                raise RodwarpError(f"rod {k} is not straight (its {name} leaves the chord by "
                                   f"{worst[k] / (2 * rods.radii[k]):.3g} d); rigid rods must be straight: "
                                   f"use rod_model='elastic' (--rod-model elastic)")
        idx = np.stack([a, b], axis=1).ravel()
        fixed = np.logical_or.reduceat(pinned, off[:-1]) if rods.n_rods else np.zeros(0, bool)
        out = RodSet(rods.points[idx], np.arange(rods.n_rods + 1) * 2, rods.radii, units=rods.units,
                     rest_points=None, velocities=None if rods.velocities is None else rods.velocities[idx],
                     box=rods.box, attrs=dict(rods.attrs))
        return out, np.repeat(fixed, 2)

    # ------------------------------------------------------------------ walls
    @property
    def planes(self) -> list[Plane]:
        """The plane walls (read only; :attr:`walls` holds every wall)."""
        return [w for w in self.walls if w.kind == "plane"]

    def control(self):
        """A new :class:`~rodwarp.sim.control.Control`: every wall in place, no drive, no torque."""
        from rodwarp.sim.control import Control

        return Control(self)

    # ------------------------------------------------------------------ scene scales
    @property
    def min_diameter(self) -> float:
        """Diameter of the thinnest rod (m)."""
        # read several times per step; the radii are fixed once the model is built
        d = getattr(self, "_min_diameter", None)
        if d is None:
            d = self._min_diameter = float(2 * self.radius_np.min())
        return d

    def total_mass(self) -> float:
        return float(self.mass_np.sum() + 2.0 * self.cross_mass_np.sum())

    def rod_masses(self) -> np.ndarray:
        """Mass of every rod (kg)."""
        m = np.bincount(self.vertex_rod_np, weights=self.mass_np, minlength=self.n_rods)
        return m + 2.0 * np.bincount(self.vertex_rod_np, weights=self.cross_mass_np, minlength=self.n_rods)

    def momentum(self, v: np.ndarray) -> np.ndarray:
        """Total linear momentum (kg m/s) of vertex velocities ``v`` (V, 3), cross terms included."""
        p = (self.mass_np[:, None] * v).sum(axis=0)
        c = self.cross_mass_np[:-1, None]
        return p + (c * (v[:-1] + v[1:])).sum(axis=0)

    def state(self) -> "State":
        """A new :class:`~rodwarp.sim.state.State` at the rods' positions and velocities, t = 0."""
        from rodwarp.sim.state import State

        s = State(self)
        s.x.assign(wp.array(self.rods.points, dtype=wp.vec3d, device=self.device))
        if self.rods.velocities is not None:
            s.v.assign(wp.array(self.rods.velocities, dtype=wp.vec3d, device=self.device))
        s.director.assign(wp.array(self.director0_np, dtype=wp.vec3d, device=self.device))
        return s


def _edges(rest: np.ndarray, offsets: np.ndarray, V: int):
    """Rest length (m) of each edge at its first vertex (0 in a rod's last-vertex slot), and the
    masks of each rod's first and last vertices."""
    edge = np.linalg.norm(np.diff(rest, axis=0), axis=1)
    last = np.zeros(V, dtype=bool)
    last[offsets[1:] - 1] = True
    first = np.zeros(V, dtype=bool)
    first[offsets[:-1]] = True
    rest_length = np.zeros(V)
    rest_length[:-1] = np.where(last[:-1], 0.0, edge)
    if np.any(rest_length[~last] <= 0):
        raise RodwarpError("a rod has two coincident consecutive vertices; remove duplicate points")
    return rest_length, first, last


def _rigid_masses(edge_mass, rest_length, r, offsets, pin_in, V: int):
    """The consistent mass matrix of rigid bars [[a, b], [b, a]] and its inverse (kg, 1/kg):
    diagonal per vertex, cross term at the first vertex; 0 inverse for a fixed rod."""
    cross_mass = np.zeros(V)
    cross_inv = np.zeros(V)
    m = edge_mass[offsets[:-1]]
    L = rest_length[offsets[:-1]]
    a = m / 3.0 + m * r**2 / (4.0 * L**2)
    b = m / 6.0 - m * r**2 / (4.0 * L**2)
    mass = np.repeat(a, 2)
    cross_mass[offsets[:-1]] = b
    det = a * a - b * b
    fixed = pin_in[offsets[:-1]]
    inv_mass = np.repeat(np.where(fixed, 0.0, a / det), 2)
    cross_inv[offsets[:-1]] = np.where(fixed, 0.0, -b / det)
    return mass, cross_mass, inv_mass, cross_inv


def _lumped_masses(edge_mass, pin_in, V: int):
    """Lumped masses: each vertex carries half of each adjacent edge (no cross terms); 0
    inverse for a pinned vertex."""
    mass = 0.5 * edge_mass
    mass[1:] += 0.5 * edge_mass[:-1]
    inv_mass = np.where(pin_in, 0.0, 1.0 / mass)
    return mass, np.zeros(V), inv_mass, np.zeros(V)


def _rest_frames(x0, rest, offsets, interior, vertex_rod, N: int, V: int):
    """Rest curvature (k1, k2) in the vertex material frames, which rods are curved, and the
    initial reference directors (the rest directors carried onto the initial shape)."""
    rest_kappa = np.zeros((V, 2))
    curved = np.zeros(N, dtype=np.int32)
    t_r, u_r = _space_parallel_directors(rest, offsets)
    kap_rest = np.zeros((V, 3))
    kap_rest[interior] = t_r[np.flatnonzero(interior)] - t_r[np.flatnonzero(interior) - 1]
    np.maximum.at(curved, vertex_rod, (np.linalg.norm(kap_rest, axis=1) > 1e-9).astype(np.int32))
    director = _space_parallel_directors(x0, offsets)[1]
    for k in np.flatnonzero(curved):
        a_, b_ = offsets[k], offsets[k + 1]
        tk, uk = t_r[a_:b_ - 1], u_r[a_:b_ - 1]
        _, m1, m2 = _vertex_frame(tk, uk)
        kap = kap_rest[a_ + 1:b_ - 1]
        rest_kappa[a_ + 1:b_ - 1, 0] = np.sum(kap * m1, axis=1)
        rest_kappa[a_ + 1:b_ - 1, 1] = np.sum(kap * m2, axis=1)
        if np.allclose(x0[a_:b_], rest[a_:b_], rtol=0, atol=1e-12):
            director[a_:b_ - 1] = uk
        else:  # carry the rest directors onto the current shape edge by edge
            t_c = _unit(np.diff(x0[a_:b_], axis=0))
            u_c = np.stack([_window_rotation(x0[a_:b_], rest[a_:b_], j) @ uk[j] for j in range(len(t_c))])
            u_c -= t_c * np.sum(u_c * t_c, axis=1, keepdims=True)
            director[a_:b_ - 1] = _unit(u_c)
        director[b_ - 1] = director[b_ - 2]
    return rest_kappa, curved, director


def checked_box(box, names=("box lower corner", "box upper corner")) -> np.ndarray:
    """A container's corners (lower, upper) as a (2, 3) array (m): finite, within 1e6 m of the
    origin, upper above lower on every axis.

    Parameters
    ----------
    box : sequence of two (3,) array_like
        Lower corner, upper corner (m).
    names : (str, str)
        How messages name the two corners (the Python arguments: ``lower``, ``upper``).

    Raises
    ------
    TypeError
        A corner that is not 3 numbers.
    RodwarpError
        A coordinate out of range, or the upper corner not above the lower one.
    """
    rows = []
    for name, corner in zip(names, box if isinstance(box, (list, tuple, np.ndarray)) else ()):
        try:
            c = np.asarray(corner, dtype=np.float64)
        except (TypeError, ValueError):
            c = None
        if c is None or c.shape != (3,) or isinstance(corner, (str, bytes)):
            raise RodwarpTypeError(f"{name} must be 3 numbers (x, y, z) in m, got {corner!r}")
        for axis, v in zip("xyz", c):
            real(f"{name} {axis}", float(v), ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, unit="m")
        rows.append(c)
    if len(rows) != 2 or len(box) != 2:
        raise RodwarpTypeError(f"box must be two corners (lower, upper) of 3 numbers each in m, got {box!r}")
    b = np.stack(rows)
    if np.any(b[1] <= b[0]):
        raise RodwarpError(f"{names[1]} {b[1].tolist()} must exceed {names[0]} {b[0].tolist()} on every axis")
    return b


def _structs():
    from rodwarp.kernels import structs

    return structs
