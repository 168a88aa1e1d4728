"""Static description of a rod scene (Model) and its evolving arrays (State).

Follows the Model / State / solver split of Warp's simulation examples and of Newton:
the :class:`Model` holds what does not change during a run (masses, rest lengths, stiffness,
boundaries), a :class:`State` holds positions, velocities, time and the contact impulses the
solver reuses to warm-start the next step, and :class:`rodwarp.solver.RodSolver` advances
``state_in`` to ``state_out``.

All quantities are SI (m, kg, s, N, Pa).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from rodwarp import _warp
from rodwarp.errors import RodwarpError
from rodwarp.rodset import RodSet


@dataclass(frozen=True)
class Material:
    """Isotropic elastic material.

    Parameters
    ----------
    young : float
        Young's modulus E (Pa).
    density : float
        Mass density rho (kg/m^3).
    poisson : float
        Poisson ratio nu; sets the shear modulus G = E / (2 (1 + nu)) used by twist.
    """

    young: float = 200e9
    density: float = 7850.0
    poisson: float = 0.3

    def __post_init__(self):
        if not (self.young > 0 and math.isfinite(self.young)):
            raise RodwarpError(f"Young's modulus must be positive, got {self.young}; pass e.g. --young 2e11")
        if not (self.density > 0 and math.isfinite(self.density)):
            raise RodwarpError(f"density must be positive, got {self.density}; pass e.g. --density 7850")
        if not (-1.0 < self.poisson < 0.5):
            raise RodwarpError(f"Poisson ratio must lie in (-1, 0.5), got {self.poisson}")

    @property
    def shear(self) -> float:
        """Shear modulus G (Pa)."""
        return self.young / (2.0 * (1.0 + self.poisson))

    @property
    def wave_speed(self) -> float:
        """Axial wave speed sqrt(E / rho) (m/s)."""
        return math.sqrt(self.young / self.density)


STEEL = Material()


@dataclass
class Plane:
    """Half-space boundary {x : n . x >= offset} with Coulomb friction.

    Parameters
    ----------
    normal : (3,) array
        Unit normal pointing into the allowed region.
    offset : float
        Plane position n . x at rest (m).
    mu : float
        Friction coefficient against rods.
    moving : bool
        Whether the plane follows the container drive (see :meth:`Model.set_drive`).
    name : str
        Label used in messages and outputs.
    """

    normal: np.ndarray
    offset: float
    mu: float = 0.2
    moving: bool = False
    name: str = "plane"


@dataclass
class Drive:
    """Prescribed container displacement A sin(2 pi f t) along ``direction`` (m, Hz)."""

    amplitude: float = 0.0
    frequency: float = 0.0
    direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    phase_time: float = 0.0

    def displacement(self, t: float) -> float:
        if self.amplitude == 0.0 or self.frequency == 0.0:
            return 0.0
        return self.amplitude * math.sin(2.0 * math.pi * self.frequency * (t - self.phase_time))

    @property
    def peak_speed(self) -> float:
        return 2.0 * math.pi * self.frequency * abs(self.amplitude)


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
        Body acceleration (m/s^2); the default is Earth gravity along -z.
    mu : float
        Rod-rod friction coefficient.
    damping : float
        Viscous damping rate gamma (1/s): force -gamma m v on every vertex. Off by default.
    pinned : array of int, optional
        Vertex indices held fixed (infinite mass); used for clamped or pinned validation scenes.
    contact_distance : float, optional
        Surface gap below which two rods count as touching (m); default d_min / 10.
    rod_contacts : bool
        Detect rod-rod contacts (off for single-rod validation scenes).
    extensible : bool
        Give edges the axial compliance h / (E A). Off by default: for stiff rods the
        axial strain is ~1e-8 and axial waves (kHz) are not resolved by the step, so exact
        inextensibility is the cheaper model and, unlike implicitly damped stretching, it
        conserves energy. Turn on to measure axial deformation.
    device : str
        ``cpu``, ``cuda``, ``cuda:N`` or ``auto``.
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
        device: str = "cpu",
    ):
        _warp.init()
        if rods.units != "m":
            if rods.units == "voxel":
                raise RodwarpError("rods are in voxels; convert with rods.to_units('m', voxel_size=...) first")
            rods = rods.to_units("m")
        if not (mu >= 0 and math.isfinite(mu)):
            raise RodwarpError(f"friction coefficient must be >= 0, got {mu}")
        if damping < 0:
            raise RodwarpError(f"damping must be >= 0, got {damping}")
        self.rods = rods
        self.material = material
        self.gravity = np.asarray(gravity, dtype=np.float64).reshape(3)
        self.mu = float(mu)
        self.damping = float(damping)
        self.device = _warp.resolve_device(device)
        self.rod_contacts = bool(rod_contacts)
        self.planes: list[Plane] = []
        self.drive = Drive()
        self.box: np.ndarray | None = None if rods.box is None else np.asarray(rods.box, float)

        N, V = rods.n_rods, rods.n_vertices
        offsets = rods.offsets.astype(np.int64)
        rest = rods.rest_points if rods.rest_points is not None else rods.points
        edge = np.linalg.norm(np.diff(rest, axis=0), axis=1)
        last = np.zeros(V, dtype=bool)
        last[offsets[1:] - 1] = True
        rest_length = np.zeros(V)
        rest_length[:-1] = np.where(last[:-1], 0.0, edge)
        if np.any(rest_length[~last] <= 0):
            raise RodwarpError("a rod has two coincident consecutive vertices; remove duplicate points")
        vertex_rod = np.repeat(np.arange(N), np.diff(offsets))
        r = rods.radii
        area = math.pi * r**2
        inertia = math.pi * r**4 / 4.0
        # lumped masses: each vertex carries half of each adjacent edge
        half = 0.5 * rest_length * area[vertex_rod] * material.density
        mass = half.copy()
        mass[1:] += half[:-1]
        inv_mass = 1.0 / mass
        self.pinned = np.zeros(V, dtype=bool)
        if pinned is not None:
            idx = np.asarray(pinned, dtype=np.int64).ravel()
            if idx.size and (idx.min() < 0 or idx.max() >= V):
                raise RodwarpError(f"pinned vertex index out of range 0..{V - 1}")
            self.pinned[idx] = True
            inv_mass[idx] = 0.0
        compliance = np.where(last | (not extensible), 0.0, rest_length / (material.young * area[vertex_rod]))

        # natural curvature: rest curvature vectors kappa_bar_i at interior vertices; only a
        # curved rest shape switches the per-step frame estimate on (straight rods skip it)
        rest_kappa = np.zeros((V, 3))
        first = np.zeros(V, dtype=bool)
        first[offsets[:-1]] = True
        interior = ~first & ~last
        idx = np.flatnonzero(interior)
        if idx.size:
            tp = (rest[idx + 1] - rest[idx]) / rest_length[idx, None]
            tm = (rest[idx] - rest[idx - 1]) / rest_length[idx - 1, None]
            rest_kappa[idx] = tp - tm
        self.curved = bool(idx.size and np.max(np.linalg.norm(rest_kappa, axis=1)) > 1e-9)
        self.rest_kappa_np = rest_kappa

        self.n_rods, self.n_vertices = N, V
        self.seg_vertex_np = np.flatnonzero(~last).astype(np.int32)
        self.n_segments = int(self.seg_vertex_np.size)
        self.mass_np = mass
        self.inv_mass_np = inv_mass
        self.rest_length_np = rest_length
        self.vertex_rod_np = vertex_rod.astype(np.int32)
        self.bend_stiffness_np = material.young * inertia
        self.radius_np = r.astype(np.float64)
        self.contact_distance = float(contact_distance) if contact_distance is not None else 0.1 * float(2 * r.min())

        d = self.device
        self.rod_start = wp.array(offsets.astype(np.int32), dtype=wp.int32, device=d)
        self.vertex_rod = wp.array(self.vertex_rod_np, dtype=wp.int32, device=d)
        self.seg_vertex = wp.array(self.seg_vertex_np, dtype=wp.int32, device=d)
        self.mass = wp.array(mass, dtype=wp.float64, device=d)
        self.inv_mass = wp.array(inv_mass, dtype=wp.float64, device=d)
        self.rest_length = wp.array(rest_length, dtype=wp.float64, device=d)
        self.compliance = wp.array(compliance, dtype=wp.float64, device=d)
        self.bend_stiffness = wp.array(self.bend_stiffness_np, dtype=wp.float64, device=d)
        self.rod_radius = wp.array(self.radius_np, dtype=wp.float64, device=d)
        self.rest_x = wp.array(rest, dtype=wp.vec3d, device=d)
        self.rest_kappa = wp.array(rest_kappa, dtype=wp.vec3d, device=d)

    # ------------------------------------------------------------------ boundaries
    def add_plane(self, normal, offset: float, *, mu: float | None = None, moving: bool = False, name: str = "plane") -> Plane:
        """Add a half-space wall {x : n . x >= offset}; returns the :class:`Plane`."""
        n = np.asarray(normal, dtype=np.float64).reshape(3)
        ln = np.linalg.norm(n)
        if not ln > 0:
            raise RodwarpError("plane normal must be a non-zero vector")
        plane = Plane(n / ln, float(offset), self.mu if mu is None else float(mu), bool(moving), name)
        self.planes.append(plane)
        return plane

    def add_box(self, lower, upper, *, walls=("floor", "x-", "x+", "y-", "y+"), mu: float | None = None, moving: bool = False):
        """Add the walls of an axis-aligned container (z up).

        Parameters
        ----------
        lower, upper : (3,) float
            Container corners (m).
        walls : sequence of str
            Which of ``floor``, ``ceiling``, ``x-``, ``x+``, ``y-``, ``y+`` to add; leave a name
            out to remove that wall (the stability test keeps only the floor).
        """
        lo = np.asarray(lower, float)
        hi = np.asarray(upper, float)
        if np.any(hi <= lo):
            raise RodwarpError(f"box upper corner {hi.tolist()} must exceed lower corner {lo.tolist()}")
        spec = {
            "floor": ((0, 0, 1), lo[2]), "ceiling": ((0, 0, -1), -hi[2]),
            "x-": ((1, 0, 0), lo[0]), "x+": ((-1, 0, 0), -hi[0]),
            "y-": ((0, 1, 0), lo[1]), "y+": ((0, -1, 0), -hi[1]),
        }
        for w in walls:
            if w not in spec:
                raise RodwarpError(f"unknown wall '{w}'; use floor, ceiling, x-, x+, y-, y+")
            n, off = spec[w]
            self.add_plane(n, off, mu=mu, moving=moving, name=w)
        self.box = np.stack([lo, hi])

    def remove_planes(self, names) -> None:
        """Remove walls by name (e.g. the side walls before the stability test)."""
        names = set(names)
        self.planes = [p for p in self.planes if p.name not in names]

    def set_drive(self, amplitude: float, frequency: float, direction=(0.0, 0.0, 1.0), phase_time: float = 0.0) -> None:
        """Moving planes follow x = A sin(2 pi f (t - phase_time)) along ``direction`` (m, Hz)."""
        if frequency < 0:
            raise RodwarpError(f"drive frequency must be >= 0 Hz, got {frequency}")
        d = np.asarray(direction, float)
        self.drive = Drive(float(amplitude), float(frequency), d / np.linalg.norm(d), float(phase_time))

    def plane_kinematics(self, t: float, dt: float):
        """Plane normals, offsets at time t and mean velocities over [t, t + dt]."""
        P = len(self.planes)
        normals = np.zeros((max(P, 1), 3))
        offsets = np.zeros(max(P, 1))
        vel = np.zeros((max(P, 1), 3))
        mus = np.zeros(max(P, 1))
        d0 = self.drive.displacement(t)
        d1 = self.drive.displacement(t + dt)
        for k, p in enumerate(self.planes):
            normals[k] = p.normal
            mus[k] = p.mu
            offsets[k] = p.offset
            if p.moving:
                offsets[k] += float(p.normal @ self.drive.direction) * d0
                vel[k] = self.drive.direction * ((d1 - d0) / dt)
        return normals, offsets, vel, mus

    def floor_height(self, t: float) -> float | None:
        """Height z (m) at time t of the floor (the plane named ``floor``, moving with the
        drive when it is ``moving``); None when the scene has no floor."""
        for p in self.planes:
            if p.name == "floor":
                z = p.offset / p.normal[2] if abs(p.normal[2]) > 0 else p.offset
                if p.moving:
                    z += float(self.drive.direction[2]) * self.drive.displacement(t)
                return float(z)
        return None

    # ------------------------------------------------------------------ scene scales
    @property
    def min_diameter(self) -> float:
        return float(2 * self.radius_np.min())

    def total_mass(self) -> float:
        return float(self.mass_np.sum())

    def state(self) -> "State":
        """A new :class:`State` at the rods' current positions and velocities, t = 0."""
        s = State(self)
        x = self.rods.points if self.rods.units == "m" else self.rods.to_units("m").points
        s.x.assign(wp.array(x, dtype=wp.vec3d, device=self.device))
        if self.rods.velocities is not None:
            s.v.assign(wp.array(self.rods.velocities, dtype=wp.vec3d, device=self.device))
        return s


class State:
    """Evolving arrays of a scene: positions, velocities, time and solver memory.

    ``contact_*`` and ``plane_impulse`` are the impulses of the last step, kept so the next
    step can warm-start Gauss-Seidel; checkpoints save them so a resumed run is bit-identical.
    """

    def __init__(self, model: Model, contact_capacity: int = 0):
        d = model.device
        V = model.n_vertices
        self.model = model
        self.time = 0.0
        self.step_index = 0
        self.x = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.v = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.plane_impulse = wp.zeros(V * max(len(model.planes), 1), dtype=wp.vec3d, device=d)
        self.contact_count = 0
        self.allocate_contacts(max(contact_capacity, 16))

    def allocate_contacts(self, capacity: int) -> None:
        """(Re)allocate contact storage for ``capacity`` contacts (content is discarded)."""
        d = self.model.device
        self.contact_capacity = capacity
        # keys need 2x room for wp.utils.radix_sort_pairs
        self.contact_key = wp.zeros(2 * capacity, dtype=wp.int64, device=d)
        self.contact_seg = wp.zeros(capacity, dtype=wp.vec2i, device=d)
        self.contact_st = wp.zeros(capacity, dtype=wp.vec2d, device=d)
        self.contact_normal = wp.zeros(capacity, dtype=wp.vec3d, device=d)
        self.contact_gap = wp.zeros(capacity, dtype=wp.float64, device=d)
        self.contact_impulse = wp.zeros(capacity, dtype=wp.vec3d, device=d)

    def ensure_plane_storage(self) -> None:
        n = self.model.n_vertices * max(len(self.model.planes), 1)
        if self.plane_impulse.shape[0] != n:
            self.plane_impulse = wp.zeros(n, dtype=wp.vec3d, device=self.model.device)

    def positions(self) -> np.ndarray:
        """Vertex positions (V, 3) in m, as a NumPy copy."""
        return self.x.numpy().copy()

    def velocities(self) -> np.ndarray:
        """Vertex velocities (V, 3) in m/s, as a NumPy copy."""
        return self.v.numpy().copy()

    def copy_from(self, other: "State") -> None:
        """Make this state an exact copy of ``other`` (same model)."""
        self.time = other.time
        self.step_index = other.step_index
        self.x.assign(other.x)
        self.v.assign(other.v)
        if self.plane_impulse.shape != other.plane_impulse.shape:
            self.plane_impulse = wp.zeros_like(other.plane_impulse)
        self.plane_impulse.assign(other.plane_impulse)
        if self.contact_capacity != other.contact_capacity:
            self.allocate_contacts(other.contact_capacity)
        for name in ("contact_key", "contact_seg", "contact_st", "contact_normal", "contact_gap", "contact_impulse"):
            getattr(self, name).assign(getattr(other, name))
        self.contact_count = other.contact_count

    def to_numpy(self) -> dict:
        """Every array of the state as NumPy (for checkpoints)."""
        c = self.contact_count
        return {
            "time": np.float64(self.time),
            "step_index": np.int64(self.step_index),
            "x": self.x.numpy(),
            "v": self.v.numpy(),
            "plane_impulse": self.plane_impulse.numpy(),
            "contact_key": self.contact_key.numpy()[:c],
            "contact_seg": self.contact_seg.numpy()[:c],
            "contact_st": self.contact_st.numpy()[:c],
            "contact_normal": self.contact_normal.numpy()[:c],
            "contact_gap": self.contact_gap.numpy()[:c],
            "contact_impulse": self.contact_impulse.numpy()[:c],
        }

    def load_numpy(self, data: dict) -> None:
        """Restore from :meth:`to_numpy` output (exactly)."""
        d = self.model.device
        self.time = float(data["time"])
        self.step_index = int(data["step_index"])
        self.x.assign(wp.array(data["x"], dtype=wp.vec3d, device=d))
        self.v.assign(wp.array(data["v"], dtype=wp.vec3d, device=d))
        self.plane_impulse = wp.array(data["plane_impulse"], dtype=wp.vec3d, device=d)
        c = int(len(data["contact_key"]))
        self.allocate_contacts(max(16, 2 * c))
        if c:
            keys = np.zeros(2 * self.contact_capacity, dtype=np.int64)
            keys[:c] = data["contact_key"]
            self.contact_key.assign(wp.array(keys, dtype=wp.int64, device=d))
            for name, dt in (("contact_seg", wp.vec2i), ("contact_st", wp.vec2d), ("contact_normal", wp.vec3d),
                             ("contact_gap", wp.float64), ("contact_impulse", wp.vec3d)):
                full = getattr(self, name).numpy()
                full[:c] = data[name]
                getattr(self, name).assign(wp.array(full, dtype=dt, device=d))
        self.contact_count = c
