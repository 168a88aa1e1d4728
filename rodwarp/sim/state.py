"""The evolving arrays of a rod scene (:class:`State`)."""

from __future__ import annotations

import numpy as np
import warp as wp


class State:
    """Positions, velocities, spins, material frames, time and the solver's memory.

    Attributes
    ----------
    x, v : wp.array of vec3d (V,)
        Vertex positions (m) and velocities (m/s).
    spin : wp.array of float64 (V,)
        Angular velocity of each edge's material about its own tangent (rad/s), stored at
        the edge's first vertex (the slot of a rod's last vertex is 0).
    theta : wp.array of float64 (V,)
        Material angle of each edge from its reference director (rad).
    director : wp.array of vec3d (V,)
        Reference director of each edge (unit, normal to the edge), time-parallel transported.
    wall_impulse : wp.array of vec3d (V * P,)
        Impulses of the vertex-wall contacts of the last step (P walls of the model).
    contact_* :
        Rod-rod contacts of the last step and their impulses.

    The impulses are kept so the next step can warm-start Gauss-Seidel; checkpoints save
    them, so a resumed run is bit-identical.
    """

    def __init__(self, model, contact_capacity: int = 0):
        d = model.device
        V = model.n_vertices
        self.model = model.finalize()  # its walls are fixed from here: the wall buffers are sized once
        self.time = 0.0
        self.step_index = 0
        self.x = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.v = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.spin = wp.zeros(V, dtype=wp.float64, device=d)
        self.theta = wp.zeros(V, dtype=wp.float64, device=d)
        self.director = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.wall_impulse = wp.zeros(V * max(len(model.walls), 1), dtype=wp.vec3d, device=d)
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

    def ensure_wall_storage(self) -> None:
        """Size the wall impulses for the model's walls (after walls were added to the model)."""
        n = self.model.n_vertices * max(len(self.model.walls), 1)
        if self.wall_impulse.shape[0] != n:
            self.wall_impulse = wp.zeros(n, dtype=wp.vec3d, device=self.model.device)

    # ------------------------------------------------------------------ device bundles
    def rod_state(self):
        """The :class:`~rodwarp.kernels.structs.RodState` view of this state (one per state,
        kept while its arrays stay the same, so the solver's recorded launches replay)."""
        from rodwarp.kernels.structs import RodState

        return cached_view(self.__dict__, "_rod_state", RodState, x=self.x, v=self.v, spin=self.spin,
                           theta=self.theta, director=self.director)

    def rod_contacts(self, count: int | None = None):
        """The :class:`~rodwarp.kernels.structs.RodContacts` view of this state's contacts
        (one per state; its count set at every call)."""
        from rodwarp.kernels.structs import RodContacts

        c = cached_view(self.__dict__, "_rod_contacts", RodContacts, seg=self.contact_seg, st=self.contact_st,
                        normal=self.contact_normal, gap=self.contact_gap, impulse=self.contact_impulse)
        n = self.contact_count if count is None else count
        if c.count != n:
            c.count = n
        return c

    # ------------------------------------------------------------------ host access
    def positions(self) -> np.ndarray:
        """Vertex positions (V, 3) in m, as a NumPy copy."""
        return self.x.numpy().copy()

    def velocities(self) -> np.ndarray:
        """Vertex velocities (V, 3) in m/s, as a NumPy copy."""
        return self.v.numpy().copy()

    def spins(self) -> np.ndarray:
        """Edge spins (V,) in rad/s (at each edge's first vertex), as a NumPy copy."""
        return self.spin.numpy().copy()

    def set_spin(self, spin) -> None:
        """Set the edge spins (rad/s): one value per rod (every edge of it) or per vertex slot (V,)."""
        m = self.model
        s = np.asarray(spin, dtype=np.float64).ravel()
        if s.size == m.n_rods:
            s = s[m.vertex_rod_np]
        if s.size != m.n_vertices:
            from rodwarp.errors import RodwarpError

            raise RodwarpError(f"spin needs {m.n_rods} (per rod) or {m.n_vertices} (per vertex slot) values, "
                               f"got {s.size}")
        s = np.where(m.inv_inertia_np > 0, s, 0.0)
        self.spin.assign(wp.array(s, dtype=wp.float64, device=m.device))

    def copy_from(self, other: "State") -> None:
        """Make this state an exact copy of ``other`` (same model)."""
        self.time = other.time
        self.step_index = other.step_index
        for name in ("x", "v", "spin", "theta", "director"):
            getattr(self, name).assign(getattr(other, name))
        if self.wall_impulse.shape != other.wall_impulse.shape:
            self.wall_impulse = wp.zeros_like(other.wall_impulse)
        self.wall_impulse.assign(other.wall_impulse)
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
            "spin": self.spin.numpy(),
            "theta": self.theta.numpy(),
            "director": self.director.numpy(),
            "wall_impulse": self.wall_impulse.numpy(),
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
        self.spin.assign(wp.array(data["spin"], dtype=wp.float64, device=d))
        self.theta.assign(wp.array(data["theta"], dtype=wp.float64, device=d))
        self.director.assign(wp.array(data["director"], dtype=wp.vec3d, device=d))
        self.wall_impulse = wp.array(data["wall_impulse"], dtype=wp.vec3d, device=d)
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


def cached_view(cache: dict, slot: str, struct_type, /, **arrays):
    """A Warp struct of ``struct_type`` holding ``arrays``, kept in ``cache[slot]`` and rebuilt
    only when one of the arrays is another object: kernels launched again on the same struct
    replay their recorded launch (:class:`rodwarp._warp.LaunchCache`)."""
    cached = cache.get(slot)
    values = tuple(arrays.values())
    if cached is None or any(a is not b for a, b in zip(cached[1], values)):
        s = struct_type()
        for name, a in arrays.items():
            setattr(s, name, a)
        cached = cache[slot] = (s, values)
    return cached[0]
