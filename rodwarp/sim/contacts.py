"""The contact pipeline of a step: broadphase (Verlet list), narrowphase, order, warm start, colours.

Three things are called contacts in rodwarp, and this module makes two of them (docs/physics.md,
"Contact"):

* *contact candidates*: segment pairs the broadphase lists as close enough to meet
  (``pairs``, the Verlet list);
* *contact points*: where the solver acts this step, one or more per candidate pair that the
  narrowphase keeps (``StepInfo.n_contacts``, speculative ones included);
* the *contacts of the packing* (touching rod pairs, one per pair) are measured from the
  contact points by :func:`rodwarp.sim.rod_contacts`, and only there.

1. broadphase: segment midpoints in a Warp hash grid; candidate segment pairs whose capsule
   gap is below the step's reach plus a skin, kept (a Verlet list) until some vertex has
   moved by half the skin;
2. narrowphase: the exact capsule gap of every candidate (segment-segment closest points,
   line contacts as two extra points); a contact point when the gap is below the contact
   distance plus what both segments can close in one step (speculative contacts: no
   tunnelling at large steps);
3. contact points sorted by key (segment pair, point) so the visiting order, and so the result,
   is the same on every run and device;
4. warm start: last step's impulse of the same key;
5. on a GPU, colours: independent sets of contact points (no shared vertex) solved concurrently.
"""

from __future__ import annotations

import time

import numpy as np
import warp as wp

from rodwarp.kernels import broadphase, friction, narrowphase


class ContactPipeline:
    """Rod-rod contact detection for a :class:`~rodwarp.sim.model.Model` (owned by a solver).

    Parameters
    ----------
    model : Model
        The scene.
    skin : float
        Extra reach of the Verlet list (m).
    launch : callable
        ``launch(stage, kernel, **kw)``: the owner's (profiled) launcher.
    timings : callable
        Returns the owner's timing dict or None.
    """

    def __init__(self, model, skin: float, launch, timings):
        d = model.device
        S = model.n_segments
        self.model = model
        self.skin = float(skin)
        self._launch = launch
        self._timings = timings
        self._mid = wp.zeros(max(S, 1), dtype=wp.vec3, device=d)
        self._scalar = wp.zeros(1, dtype=wp.float64, device=d)
        self._count = wp.zeros(1, dtype=wp.int32, device=d)
        self._grid = None
        self._cap = 0
        self.pairs_cap = max(64, 8 * S)
        self.pairs = wp.zeros(self.pairs_cap, dtype=wp.vec2i, device=d)
        self.pairs_n = None  # None: the list must be (re)built
        self.pairs_margin = 0.0
        self._x_build = wp.zeros(model.n_vertices, dtype=wp.vec3d, device=d)
        self.builds = 0
        self.colors_used = 0
        self.color_ranges: list = []
        self.grow(max(64, 4 * S))

    def grow(self, cap: int) -> None:
        d = self.model.device
        self._cap = cap
        self._raw_seg = wp.zeros(cap, dtype=wp.vec2i, device=d)
        self._raw_key = wp.zeros(2 * cap, dtype=wp.int64, device=d)
        self._raw_st = wp.zeros(cap, dtype=wp.vec2d, device=d)
        self._raw_normal = wp.zeros(cap, dtype=wp.vec3d, device=d)
        self._raw_gap = wp.zeros(cap, dtype=wp.float64, device=d)
        self._order = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._color = wp.zeros(cap, dtype=wp.int32, device=d)
        self.color_ids = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._color_keys = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self.gap_check = wp.zeros(cap, dtype=wp.float64, device=d)

    def _time(self, stage, fn, *args):
        tm = self._timings()
        t0 = time.perf_counter() if tm is not None else 0.0
        out = fn(*args)
        if tm is not None:
            tm[stage] = tm.get(stage, 0.0) + time.perf_counter() - t0
        return out

    def detect(self, state_in, state_out, vmax: float, dt: float) -> int:
        """Contacts of this step into ``state_out`` (sorted by key); returns their number."""
        m = self.model
        dev = m.device
        S = m.n_segments
        base = m.contact_distance
        # speculative reach of this step; the pair list is rebuilt when it no longer covers it
        need = base + 2.0 * vmax * dt
        rebuild = self.pairs_n is None or need > self.pairs_margin
        if not rebuild:
            self._scalar.zero_()
            self._launch("broadphase", broadphase.max_displacement, dim=m.n_vertices, device=dev,
                         inputs=[state_in.x, self._x_build, self._scalar])
            moved = float(self._scalar.numpy()[0])
            rebuild = 2.0 * moved + need > self.pairs_margin
        if rebuild:
            self.build_pairs(state_in, need)
        n_pairs = self.pairs_n
        while True:
            self._count.zero_()
            if n_pairs:
                self._launch("narrowphase", narrowphase.narrowphase_pairs, dim=n_pairs, device=dev, inputs=[
                    self.pairs, n_pairs, S, m.arrays.seg_vertex, m.arrays.vertex_rod, m.arrays.radius, state_in.x,
                    state_out.v, wp.float64(base), wp.float64(dt), self._cap, self._count,
                    self._raw_seg, self._raw_key, self._raw_st, self._raw_normal, self._raw_gap])
            n = int(self._count.numpy()[0])
            if n <= self._cap:
                break
            self.grow(2 * n)
        if state_out.contact_capacity < max(n, 1):
            state_out.allocate_contacts(2 * n)
        if n == 0:
            return 0
        self._launch("narrowphase", narrowphase.iota, dim=n, device=dev, inputs=[self._order])
        self._time("narrowphase", wp.utils.radix_sort_pairs, self._raw_key, self._order, n)
        wp.copy(state_out.contact_key, self._raw_key, count=n)
        self._launch("narrowphase", narrowphase.gather_contacts, dim=n, device=dev, inputs=[
            self._order, n, self._raw_seg, self._raw_st, self._raw_normal, self._raw_gap,
            state_out.contact_seg, state_out.contact_st, state_out.contact_normal, state_out.contact_gap])
        return n

    def build_pairs(self, state, need: float) -> None:
        """Broadphase: candidate segment pairs within reach + skin (a Verlet list)."""
        m = self.model
        dev = m.device
        S = m.n_segments
        self._launch("broadphase", broadphase.segment_midpoints, dim=S, device=dev,
                     inputs=[m.arrays.seg_vertex, state.x, self._mid])
        hmax = float(m.rest_length_np.max())
        rmax = float(m.radius_np.max())
        margin = need + self.skin
        query = (hmax + 2.0 * rmax + margin) * 1.0001 + 1e-6
        if self._grid is None:
            self._grid = wp.HashGrid(128, 128, 128, device=dev)
        self._time("broadphase", self._grid.build, self._mid, query)
        while True:
            self._count.zero_()
            self._launch("broadphase", broadphase.find_candidate_pairs, dim=S, device=dev, inputs=[
                self._grid.id, self._mid, m.arrays.seg_vertex, m.arrays.vertex_rod, m.arrays.radius, m.arrays.arc,
                state.x, float(query), wp.float64(margin), self.pairs_cap, self._count, self.pairs])
            n = int(self._count.numpy()[0])
            if n <= self.pairs_cap:
                break
            self.pairs_cap = 2 * n
            self.pairs = wp.zeros(self.pairs_cap, dtype=wp.vec2i, device=dev)
        self.pairs_n = n
        self.pairs_margin = margin
        wp.copy(self._x_build, state.x)
        self.builds += 1

    def warm_start(self, state_in, state_out, n: int, warm: float) -> None:
        """Last step's impulses of the same keys into ``state_out`` (split along the new normals)."""
        self._launch("narrowphase", friction.warm_start_rod_contacts, dim=n, device=self.model.device, inputs=[
            n, state_out.contact_key, state_out.contact_normal, state_in.contact_count, state_in.contact_key,
            state_in.contact_impulse, wp.float64(warm), state_out.contact_impulse])

    def color(self, state, n: int) -> None:
        """Partition contacts into independent sets (no shared vertex) for race-free Gauss-Seidel."""
        m = self.model
        dev = m.device
        self._color.fill_(-1)
        owner = wp.zeros(m.n_vertices, dtype=wp.int32, device=dev)
        remaining = wp.zeros(1, dtype=wp.int32, device=dev)
        rnd = 0
        while True:
            owner.fill_(2**31 - 1)
            remaining.zero_()
            self._launch("friction", friction.color_claim, dim=n, device=dev,
                         inputs=[n, state.contact_seg, m.arrays.seg_vertex, self._color, owner])
            self._launch("friction", friction.color_commit, dim=n, device=dev,
                         inputs=[n, state.contact_seg, m.arrays.seg_vertex, rnd, owner, self._color, remaining])
            rnd += 1
            if int(remaining.numpy()[0]) == 0:
                break
        self.colors_used = rnd
        wp.copy(self._color_keys, self._color, count=n)
        self._launch("narrowphase", narrowphase.iota, dim=n, device=dev, inputs=[self.color_ids])
        wp.utils.radix_sort_pairs(self._color_keys, self.color_ids, n)
        counts = np.bincount(self._color.numpy()[:n], minlength=rnd)
        edges = np.concatenate([[0], np.cumsum(counts)])
        self.color_ranges = [(int(edges[i]), int(edges[i + 1])) for i in range(rnd) if counts[i] > 0]
