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

import math
import time

import numpy as np
import warp as wp

from rodwarp.kernels import broadphase, coloring, narrowphase
from rodwarp.kernels.structs import RawContacts
from rodwarp.sim.state import cached_view


#: per-point arrays of :class:`ContactBuffers` and their types (``contact_<name>`` in a checkpoint)
_POINT_DTYPES = {"seg": wp.vec2i, "st": wp.vec2d, "normal": wp.vec3d, "gap": wp.float64, "impulse": wp.vec3d}
_POINT_ARRAYS = tuple(_POINT_DTYPES)


class ContactBuffers:
    """One set of contact points on the device, and the wall impulses of the same step.

    Attributes
    ----------
    count : int
        Contact points held.
    key : wp.array of int64 (2 capacity,)
        Sort key of each point (segment pair and point); twice the room for the radix sort.
    seg, st, normal, gap : wp.array (capacity,)
        Segment pair, closest-point parameters, unit normal (from the second segment to the
        first) and surface gap (m) at the start of the step.
    impulse : wp.array of vec3d (capacity,)
        The point's impulse (N s) once solved.
    wall_impulse : wp.array of vec3d (V * P,)
        Impulses (N s) of the vertex-wall contacts (P walls of the model, at least one slot).
    """

    def __init__(self, model, capacity: int):
        self.model = model
        self.count = 0
        self.wall_impulse = wp.zeros(model.n_vertices * max(len(model.walls), 1), dtype=wp.vec3d, device=model.device)
        self.allocate(capacity)

    def allocate(self, capacity: int) -> None:
        """(Re)allocate room for ``capacity`` points (their content is discarded)."""
        d = self.model.device
        self.capacity = capacity
        # keys need 2x room for wp.utils.radix_sort_pairs
        self.key = wp.zeros(2 * capacity, dtype=wp.int64, device=d)
        for name, dtype in _POINT_DTYPES.items():
            setattr(self, name, wp.zeros(capacity, dtype=dtype, device=d))

    def view(self):
        """The :class:`~rodwarp.kernels.structs.RodContacts` struct of these points (kept while
        the arrays stay the same, so the solver's recorded launches replay)."""
        from rodwarp.kernels.structs import RodContacts

        c = cached_view(self.__dict__, "_view", RodContacts, seg=self.seg, st=self.st, normal=self.normal,
                        gap=self.gap, impulse=self.impulse)
        if c.count != self.count:
            c.count = self.count
        return c

    def copy_from(self, other: "ContactBuffers") -> None:
        if self.capacity != other.capacity:
            self.allocate(other.capacity)
        for name in _POINT_ARRAYS + ("key", "wall_impulse"):
            getattr(self, name).assign(getattr(other, name))
        self.count = other.count



class ContactPoints:
    """The contact points of a step, from :meth:`RodSolver.collide`, and the solver's memory of
    the last step's impulses (warm start).

    ``solver.collide(state_in, control, dt, contacts)`` fills :attr:`next` with the points of the
    coming step; ``solver.step(state_in, state_out, control, contacts, dt)`` solves them and, once
    the step passes its checks, makes them :attr:`last`. A step that fails leaves :attr:`last`
    as it was, so a retry from the same state warm-starts from the same impulses (bit for bit).

    Attributes
    ----------
    last : ContactBuffers
        The points and impulses of the last successful step (what a checkpoint saves, what
        :func:`rodwarp.sim.rod_contacts` measures).
    next : ContactBuffers
        The points found for the coming step.
    predicted_speed : float
        Fastest vertex speed (m/s) after the coming step's velocity predictor, which sets the
        reach of the speculative contacts (NaN when the predictor gave a non-finite speed).
    """

    def __init__(self, model, capacity: int = 16):
        self.model = model
        self.last = ContactBuffers(model, max(capacity, 16))
        self.next = ContactBuffers(model, max(capacity, 16))
        self.predicted_speed = 0.0
        self.collided_for = None  # what collide() filled ``next`` for: (state, step index, time, control, dt)

    @property
    def count(self) -> int:
        """Contact points of the last successful step."""
        return self.last.count

    @property
    def wall_impulse(self):
        """Impulses (N s) of the last step's vertex-wall contacts, (V * P,) with P walls."""
        return self.last.wall_impulse

    def commit(self) -> None:
        """Make the solved :attr:`next` points the :attr:`last` ones (the step succeeded)."""
        self.last, self.next = self.next, self.last
        self.collided_for = None

    def clear_wall_impulses(self) -> None:
        """Forget the walls' impulses (a test that switches walls: no warm start from them)."""
        self.last.wall_impulse.zero_()

    def copy_from(self, other: "ContactPoints") -> None:
        """Make these contacts an exact copy of ``other``'s last step (same model)."""
        self.last.copy_from(other.last)
        self.collided_for = None

    def to_numpy(self) -> dict:
        """The last step's points and impulses as NumPy (for checkpoints; the names are those of
        the checkpoints written before contacts left the State, so old ones load)."""
        c = self.last
        out = {f"contact_{name}": getattr(c, name).numpy()[:c.count] for name in ("key",) + _POINT_ARRAYS}
        out["wall_impulse"] = c.wall_impulse.numpy()
        return out

    def load_numpy(self, data: dict) -> None:
        """Restore from :meth:`to_numpy` output (exactly; other keys are ignored)."""
        d = self.model.device
        c = self.last
        c.wall_impulse = wp.array(data["wall_impulse"], dtype=wp.vec3d, device=d)
        n = int(len(data["contact_key"]))
        c.allocate(max(16, 2 * n))
        if n:
            keys = np.zeros(2 * c.capacity, dtype=np.int64)
            keys[:n] = data["contact_key"]
            c.key.assign(wp.array(keys, dtype=wp.int64, device=d))
            for name in _POINT_ARRAYS:
                a = getattr(c, name)
                full = a.numpy()
                full[:n] = data[f"contact_{name}"]
                a.assign(wp.array(full, dtype=a.dtype, device=d))
        c.count = n
        self.collided_for = None


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
        self._pairs_tmp = wp.zeros(self.pairs_cap, dtype=wp.vec2i, device=d)
        self._ref = wp.zeros(2 * max(S, 1), dtype=wp.vec3d, device=d)
        # the sum of the vertex positions: the pile's mean position is the frame the pair list
        # measures displacements in
        self.sums = wp.zeros(1, dtype=wp.vec3d, device=d)
        self._inv_v = wp.float64(1.0 / max(model.n_vertices, 1))
        self._flag = wp.zeros(max(S, 1), dtype=wp.int32, device=d)
        self._stale = wp.zeros(max(S, 1), dtype=wp.int32, device=d)
        self._query = 0.0
        self._grid_dims = None
        self._all = None
        self.builds = 0
        self.refreshes = 0
        self.refreshed_segments = 0
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
        raw = self._raw = RawContacts()
        raw.capacity, raw.count = cap, self._count
        raw.seg, raw.key, raw.st, raw.normal, raw.gap = (self._raw_seg, self._raw_key, self._raw_st, self._raw_normal,
                                                         self._raw_gap)
        self._order = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._color = wp.zeros(cap, dtype=wp.int32, device=d)
        self.color_ids = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._color_keys = wp.zeros(2 * cap, dtype=wp.int32, device=d)

    def _time(self, stage, fn, *args):
        tm = self._timings()
        t0 = time.perf_counter() if tm is not None else 0.0
        out = fn(*args)
        if tm is not None:
            tm[stage] = tm.get(stage, 0.0) + time.perf_counter() - t0
        return out

    def detect(self, state_in, out: "ContactBuffers", v_pred, vmax: float, dt: float) -> int:
        """Contact points of a step of ``dt`` s from ``state_in`` into ``out`` (sorted by key),
        reaching as far as the predicted velocities ``v_pred`` (largest ``vmax``, m/s) can
        carry each segment; returns their number."""
        m = self.model
        dev = m.device
        S = m.n_segments
        base = m.contact_distance
        # speculative reach of this step. Every pair not listed had a gap of at least the list's
        # margin M when the later of its two segments was last refreshed, and since then each
        # segment has moved by at most tau (the flagged ones are refreshed now) and the other by
        # at most 2 tau; so the list holds every pair within M - 3 tau, which must cover the reach.
        need = base + 2.0 * vmax * dt
        # displacements are measured from the pile's mean position: a falling or tossed pile
        # moves together, and a common translation changes no gap (kernels/broadphase.py)
        self._time("broadphase", wp.utils.array_sum, state_in.x, self.sums)
        rebuild = self.pairs_n is None or need > self.pairs_margin - 3.0 * self.tau
        if not rebuild:
            self._count.zero_()
            self._launch("broadphase", broadphase.stale_segments, dim=S, device=dev, inputs=[
                m.arrays.seg_vertex, state_in.x, self.sums, self._inv_v, self._ref, wp.float64(self.tau), self._flag,
                self._count, self._stale])
            n_stale = int(self._count.numpy()[0])
            if n_stale > self.PARTIAL_LIMIT * S:
                rebuild = True
            elif n_stale:
                rebuild = not self.refresh_pairs(state_in, n_stale)
        if rebuild:
            self.build_pairs(state_in, need)
        n_pairs = self.pairs_n
        while True:
            self._count.zero_()
            if n_pairs:
                self._launch("narrowphase", narrowphase.narrowphase_pairs, dim=n_pairs, device=dev, inputs=[
                    self.pairs, n_pairs, S, m.arrays, state_in.x, v_pred, wp.float64(base), wp.float64(dt),
                    self._raw])
            n = int(self._count.numpy()[0])
            if n <= self._cap:
                break
            self.grow(2 * n)
        if out.capacity < max(n, 1):
            out.allocate(2 * n)
        if n == 0:
            return 0
        self._time("narrowphase", self._sort, n)
        wp.copy(out.key, self._raw_key, count=n)
        self._launch("narrowphase", narrowphase.gather_contacts, dim=n, device=dev, inputs=[
            self._order, n, self._raw_seg, self._raw_st, self._raw_normal, self._raw_gap,
            out.seg, out.st, out.normal, out.gap])
        return n

    def _sort(self, n: int) -> None:
        """Contact points ordered by key: ``_raw_key`` sorted, ``_order`` the permutation.

        On the CPU the arrays are host memory and NumPy's stable sort (timsort) does it in
        place: from step to step the pair list keeps its order, so the keys arrive nearly
        sorted, which timsort finishes in about one pass (2000 keys: a few microseconds
        against 0.13 ms for Warp's radix sort). Both sorts are stable and the keys unique, so
        the order, and the trajectory, are the same."""
        if self.model.device == "cpu":
            keys = self._raw_key.numpy()[:n]
            perm = np.argsort(keys, kind="stable")
            keys[:] = keys[perm]
            self._order.numpy()[:n] = perm
            return
        self._launch("narrowphase", narrowphase.iota, dim=n, device=self.model.device, inputs=[self._order])
        wp.utils.radix_sort_pairs(self._raw_key, self._order, n)

    #: flagged share of the segments above which the whole pair list is rebuilt instead of
    #: refreshed (a refresh queries the flagged segments only, but keeps the others' pairs)
    PARTIAL_LIMIT = 0.3

    @property
    def tau(self) -> float:
        """Displacement (m) since its last refresh above which a segment's pairs are found again."""
        return 0.25 * self.skin

    def _grid_of(self, state) -> None:
        m = self.model
        self._launch("broadphase", broadphase.segment_midpoints, dim=m.n_segments, device=m.device,
                     inputs=[m.arrays.seg_vertex, state.x, self._mid])
        # a hash grid no finer than the scene needs: its build clears every cell, and a 128^3
        # grid's 2M cells cost more than hashing a few hundred rods' midpoints
        ext = m.box[1] - m.box[0] if m.box is not None else np.full(3, 128.0 * self._query)
        dims = tuple(int(min(128, max(4, math.ceil(e / self._query) + 2))) for e in ext)
        if self._grid is None or self._grid_dims != dims:
            self._grid = wp.HashGrid(*dims, device=m.device)
            self._grid_dims = dims
        self._time("broadphase", self._grid.build, self._mid, self._query)

    def build_pairs(self, state, need: float) -> None:
        """Broadphase: candidate segment pairs within reach + skin (a Verlet list)."""
        m = self.model
        dev = m.device
        S = m.n_segments
        hmax = float(m.rest_length_np.max())
        rmax = float(m.radius_np.max())
        margin = need + self.skin
        self._query = (hmax + 2.0 * rmax + margin) * 1.0001 + 1e-6
        self._grid_of(state)
        if self._all is None:
            self._all = wp.array(np.arange(S, dtype=np.int32), device=dev)
        self._flag.fill_(1)
        while True:
            self._count.zero_()
            self._launch("broadphase", broadphase.find_pairs_of_flagged, dim=S, device=dev, inputs=[
                self._grid.id, self._all, self._flag, self._mid, m.arrays, state.x, float(self._query),
                wp.float64(margin), self.pairs_cap, self._count, self.pairs, self.sums, self._inv_v,
                self._ref])
            n = int(self._count.numpy()[0])
            if n <= self.pairs_cap:
                break
            self._grow_pairs(2 * n)
        self.pairs_n = n
        self.pairs_margin = margin
        self.builds += 1

    def _grow_pairs(self, cap: int) -> None:
        self.pairs_cap = cap
        self.pairs = wp.zeros(cap, dtype=wp.vec2i, device=self.model.device)
        self._pairs_tmp = wp.zeros(cap, dtype=wp.vec2i, device=self.model.device)

    def refresh_pairs(self, state, n_stale: int) -> bool:
        """Partial refresh of the Verlet list: the pairs of the ``n_stale`` flagged segments
        replaced by those within the list's margin now. Returns False (nothing changed but the
        flagged segments' references) when the list would outgrow its capacity: rebuild then."""
        m = self.model
        dev = m.device
        self._grid_of(state)
        self._count.zero_()
        if self.pairs_n:
            self._launch("broadphase", broadphase.drop_pairs_of_flagged, dim=self.pairs_n, device=dev,
                         inputs=[self.pairs, self._flag, self._pairs_tmp, self._count])
        self._launch("broadphase", broadphase.find_pairs_of_flagged, dim=n_stale, device=dev, inputs=[
            self._grid.id, self._stale, self._flag, self._mid, m.arrays, state.x, float(self._query),
            wp.float64(self.pairs_margin), self.pairs_cap, self._count, self._pairs_tmp, self.sums,
            self._inv_v, self._ref])
        n = int(self._count.numpy()[0])
        if n > self.pairs_cap:
            return False
        self.pairs, self._pairs_tmp = self._pairs_tmp, self.pairs
        self.pairs_n = n
        self.refreshes += 1
        self.refreshed_segments += n_stale
        return True

    def warm_start(self, last: "ContactBuffers", out: "ContactBuffers", n: int, warm: float) -> None:
        """``last`` step's impulses of the same keys into ``out`` (split along the new normals)."""
        self._launch("narrowphase", coloring.warm_start_rod_contacts, dim=n, device=self.model.device, inputs=[
            n, out.key, out.normal, last.count, last.key, last.impulse, wp.float64(warm), out.impulse])

    def color(self, contacts: "ContactBuffers", n: int) -> None:
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
            self._launch("friction", coloring.color_claim, dim=n, device=dev,
                         inputs=[n, contacts.seg, m.arrays.seg_vertex, self._color, owner])
            self._launch("friction", coloring.color_commit, dim=n, device=dev,
                         inputs=[n, contacts.seg, m.arrays.seg_vertex, rnd, owner, self._color, remaining])
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
