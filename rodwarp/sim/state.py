"""The evolving arrays of a rod scene (:class:`State`)."""

from __future__ import annotations

import numpy as np
import warp as wp


class State:
    """Positions, velocities, spins, material frames and time of a rod scene.

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
    time : float
        Simulated time (s).
    step_index : int
        Steps taken to reach this state.

    The contacts of a step and the impulses that warm-start the next one live in
    :class:`~rodwarp.sim.contacts.Contacts`, not here (as in Newton).
    """

    def __init__(self, model):
        d = model.device
        V = model.n_vertices
        self.model = model
        self.time = 0.0
        self.step_index = 0
        self.x = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.v = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.spin = wp.zeros(V, dtype=wp.float64, device=d)
        self.theta = wp.zeros(V, dtype=wp.float64, device=d)
        self.director = wp.zeros(V, dtype=wp.vec3d, device=d)

    # ------------------------------------------------------------------ device bundles
    def rod_state(self):
        """The :class:`~rodwarp.kernels.structs.RodState` view of this state (one per state,
        kept while its arrays stay the same, so the solver's recorded launches replay)."""
        from rodwarp.kernels.structs import RodState

        return cached_view(self.__dict__, "_rod_state", RodState, x=self.x, v=self.v, spin=self.spin,
                           theta=self.theta, director=self.director)

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
        for name in _ARRAYS:
            getattr(self, name).assign(getattr(other, name))

    def to_numpy(self) -> dict:
        """Every array of the state as NumPy (for checkpoints)."""
        return {"time": np.float64(self.time), "step_index": np.int64(self.step_index),
                **{name: getattr(self, name).numpy() for name in _ARRAYS}}

    def load_numpy(self, data: dict) -> None:
        """Restore from :meth:`to_numpy` output (exactly; other keys are ignored)."""
        d = self.model.device
        self.time = float(data["time"])
        self.step_index = int(data["step_index"])
        for name in _ARRAYS:
            a = getattr(self, name)
            a.assign(wp.array(data[name], dtype=a.dtype, device=d))


#: the evolving arrays of a :class:`State`
_ARRAYS = ("x", "v", "spin", "theta", "director")


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
