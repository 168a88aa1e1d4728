"""Time stepping of rod scenes: implicit bending, exact inextensibility, Gauss-Seidel contact.

One step of :meth:`RodSolver.step` (all on the model's device):

1. velocity predictor, one thread per rod: damping, gravity and, for symplectic (explicit)
   bending, the bending force;
2. contact detection at the start-of-step positions: hash grid over segment midpoints, exact
   segment-segment closest points, speculative margin = contact distance + travel in one step;
   contacts sorted by segment pair so the order (and hence the result) is deterministic;
3. warm start: impulses of the same segment pairs (and vertex-plane pairs) from the last step;
4. ``iterations`` Gauss-Seidel sweeps over rod-rod contacts, rod-plane contacts and exact
   per-rod solves of all bending constraints (implicit bending) and edge-length constraints;
   every block uses the same mass metric, so the converged step is implicit Euler with
   exact Coulomb contact and its fixed point is the static equilibrium;
5. x' = x + dt v'.

``state_in`` is never modified, so a step that fails its checks leaves the last good state.
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import numpy as np
import warp as wp

from rodwarp.errors import RodwarpError, SimulationBlowUp
from rodwarp.kernels import broadphase, contacts, elastics, friction, solve
from rodwarp.model import Model, State


@dataclass
class StepInfo:
    """Diagnostics of one step.

    Attributes
    ----------
    contact_residual : float
        Largest velocity change (m/s) that any contact caused in the last Gauss-Seidel sweep;
        0 for a fully converged solve.
    stretch_residual : float
        Largest edge-length error (m) before the last stretch projection.
    """

    step: int
    time: float
    dt: float
    iterations: int  # sweeps actually run
    n_contacts: int
    contact_residual: float
    stretch_residual: float
    max_speed: float
    theta: float


class RodSolver:
    """Advance a :class:`~rodwarp.model.Model` from ``state_in`` to ``state_out``.

    Parameters
    ----------
    model : Model
        The scene.
    iterations : int
        Most Gauss-Seidel sweeps per step (contacts, planes, bending and stretching each).
    tolerance : float
        Stop sweeping early once a sweep changes no contact velocity by more than this
        (m/s) and no edge length is off by more than 1e-6 of the shortest edge; 0 always
        runs ``iterations`` sweeps. Checked every second sweep.
    bending : {"auto", "implicit", "explicit"}
        Bending integration. ``auto`` uses symplectic (explicit) bending when the step is
        below its stability bound, which conserves energy, and implicit Euler above it.
    coloring : {"auto", "on", "off"}
        Colour rod-rod contacts so that each colour can be solved in parallel without data
        races. ``auto`` colours on CUDA only; a CPU launch is already sequential.
    warm_start : float
        Fraction of last step's impulses reused (0 disables warm starting).
    baumgarte : float
        Fraction of an existing overlap removed per step.
    penetration_limit : float
        A step whose deepest rod overlap exceeds this fraction of the smallest diameter
        raises :class:`SimulationBlowUp`.
    speed_limit : float, optional
        Speeds above this (m/s) are treated as a blow-up; default 20 x the scene's
        characteristic speed (free fall over the scene height, drive speed, initial speeds
        and the speed the initial elastic energy could give all rods).
    allow_unstable : bool
        Accept a step above the stability bound with a warning instead of an error.
    energy_check_every : int
        Steps between energy-jump checks (0 disables them).
    skin : float, optional
        Extra reach of the broadphase pair list (m); the list is rebuilt when a vertex has
        moved by half of it. Default d_min + h_max / 5 (measured knee, benchmarks).
    """

    def __init__(
        self,
        model: Model,
        *,
        iterations: int = 40,
        tolerance: float = 1e-6,
        bending: str = "auto",
        coloring: str = "auto",
        warm_start: float = 1.0,
        baumgarte: float = 0.5,
        penetration_limit: float = 0.25,
        speed_limit: float | None = None,
        allow_unstable: bool = False,
        energy_check_every: int = 10,
        skin: float | None = None,
    ):
        if iterations < 1:
            raise RodwarpError(f"iterations must be >= 1, got {iterations}")
        if bending not in ("auto", "implicit", "explicit"):
            raise RodwarpError(f"bending must be auto, implicit or explicit, got '{bending}'")
        if coloring not in ("auto", "on", "off"):
            raise RodwarpError(f"coloring must be auto, on or off, got '{coloring}'")
        self.model = model
        self.iterations = int(iterations)
        self.tolerance = float(tolerance)
        self.length_tolerance = 1e-6 * float(model.rest_length_np[model.rest_length_np > 0].min())
        self.bending = bending
        self.coloring = coloring == "on" or (coloring == "auto" and wp.get_device(model.device).is_cuda)
        self.warm_start = float(warm_start)
        self.baumgarte = float(baumgarte)
        self.penetration_limit = float(penetration_limit)
        self.allow_unstable = bool(allow_unstable)
        self._speed_limit = speed_limit
        self._v_elastic = None
        self._eb_dt = None
        self._last_mech = None
        self.energy_check_every = int(energy_check_every)
        d = model.device
        V, S = model.n_vertices, model.n_segments
        self._diag = wp.zeros(V, dtype=wp.float64, device=d)
        self._off1 = wp.zeros(V, dtype=wp.float64, device=d)
        self._rhs = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._sdir = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._lam = wp.zeros(V, dtype=wp.float64, device=d)
        self._blam = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._bdiag = wp.zeros(V, dtype=wp.float64, device=d)
        self._boff1 = wp.zeros(V, dtype=wp.float64, device=d)
        self._boff2 = wp.zeros(V, dtype=wp.float64, device=d)
        self._bfactor_dt = None
        self._bcoef = wp.zeros(V, dtype=wp.vec4d, device=d)
        self._btarget = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._dlam = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._mid = wp.zeros(max(S, 1), dtype=wp.vec3, device=d)
        self._scalar = wp.zeros(4, dtype=wp.float64, device=d)
        self._residual = wp.zeros(1, dtype=wp.float64, device=d)
        self._sresidual = wp.zeros(1, dtype=wp.float64, device=d)
        self._count = wp.zeros(1, dtype=wp.int32, device=d)
        self._grid = None
        self._cap = 0
        # Verlet list of candidate segment pairs, valid while vertices move < skin / 2
        self.skin = model.min_diameter + 0.2 * float(model.rest_length_np.max()) if skin is None else float(skin)
        self._pairs_cap = max(64, 8 * S)
        self._pairs = wp.zeros(self._pairs_cap, dtype=wp.vec2i, device=d)
        self._pairs_n = None
        self._pairs_margin = 0.0
        self._x_build = wp.zeros(V, dtype=wp.vec3d, device=d)
        self.pair_builds = 0
        self._grow(max(64, 4 * S))
        self._plane_gap = wp.zeros(V * max(len(model.planes), 1), dtype=wp.float64, device=d)
        self._active = wp.zeros(V, dtype=wp.int32, device=d)
        self._n_active = wp.zeros(1, dtype=wp.int32, device=d)
        self._solve_out = wp.zeros(3, dtype=wp.float64, device=d)
        # sequential devices run the whole solve in one launch (same order, no launch overhead)
        self.fused = (not self.coloring) and not wp.get_device(model.device).is_cuda
        self.last_info: StepInfo | None = None
        # per-stage kernel seconds (elastics, broadphase, narrowphase, friction, checks) when
        # profiling; None (no synchronisation, no overhead) otherwise
        self.timings: dict | None = None
        self.colors_used = 0

    # ------------------------------------------------------------------ stability
    def explicit_bending_dt(self) -> float:
        if self._eb_dt is None:
            self._eb_dt = self._explicit_bending_dt()
        return self._eb_dt

    def _explicit_bending_dt(self) -> float:
        """Largest stable step of symplectic (explicit) bending (s): 2 / omega_max.

        omega_max^2 is bounded by the Gershgorin row sums of M^-1 K, which is exact for the
        uniform stencil (16 E I / (rho A h^4)).
        """
        m = self.model
        rows = np.zeros(m.n_vertices)
        offs = m.rods.offsets
        h = m.rest_length_np
        free = (~m.pinned).astype(np.float64)
        for r in range(m.n_rods):
            a, b = offs[r], offs[r + 1]
            if b - a < 3:
                continue
            i = np.arange(a + 1, b - 1)
            cm = 1.0 / h[i - 1]
            cp = 1.0 / h[i]
            c0 = cm + cp
            k = m.bend_stiffness_np[r] * 2.0 / (h[i - 1] + h[i])
            # pinned vertices do not move, so their columns do not enter the eigenproblem
            tot = cm * free[i - 1] + c0 * free[i] + cp * free[i + 1]
            np.add.at(rows, i - 1, k * cm * tot)
            np.add.at(rows, i, k * c0 * tot)
            np.add.at(rows, i + 1, k * cp * tot)
        fr = ~m.pinned
        lam = np.max(rows[fr] / m.mass_np[fr]) if np.any(fr) else 0.0
        return math.inf if lam <= 0 else 2.0 / math.sqrt(lam)

    def explicit_stretch_dt(self) -> float:
        """Explicit axial limit h_min / sqrt(E / rho) (s); rodwarp's constraints do not need it."""
        m = self.model
        h = m.rest_length_np
        # edges with both ends pinned (a clamp's ghost edge) never move: leave them out
        moving = (h > 0) & ~(m.pinned & np.roll(m.pinned, -1))
        return float(h[moving].min() / m.material.wave_speed)

    def characteristic_speed(self) -> float:
        """Free-fall speed over the scene height plus the drive's peak speed (m/s)."""
        m = self.model
        bb = m.box if m.box is not None else m.rods.bounding_box()
        g = float(np.linalg.norm(m.gravity))
        # the fall height is the scene's extent along gravity, not its widest side
        down = m.gravity / g if g > 0 else np.array([0.0, 0.0, -1.0])
        height = float(np.abs(bb[1] - bb[0]) @ np.abs(down))
        v0 = 0.0 if m.rods.velocities is None else float(np.linalg.norm(m.rods.velocities, axis=1).max())
        return math.sqrt(2.0 * g * height) + m.drive.peak_speed + v0 + 1e-3

    def contact_dt(self) -> float:
        """Resolution bound of the contact model (s): a rod moving at the characteristic speed
        crosses at most one diameter per step, so speculative contacts see every approach
        and the linearised normals stay valid; and gravity alone moves a resting vertex by at
        most 1% of a diameter per step (g dt^2 <= 0.01 d), which keeps frictional stacks from
        creeping at the default Gauss-Seidel effort."""
        d = self.model.min_diameter
        b = d / self.characteristic_speed()
        g = float(np.linalg.norm(self.model.gravity))
        if g > 0:
            b = min(b, math.sqrt(0.01 * d / g))
        return b

    def max_stable_dt(self, bending: str | None = None) -> float:
        """Stability bound of this scene for the chosen bending integration (s)."""
        mode = bending or self.bending
        b = self.contact_dt()
        if mode == "explicit":
            b = min(b, self.explicit_bending_dt())
        return b

    def default_dt(self, safety: float = 0.5) -> float:
        """Default step: ``safety`` x the stability bound, and at least 40 steps per drive period."""
        dt = safety * self.max_stable_dt()
        f = self.model.drive.frequency
        if f > 0:
            dt = min(dt, 1.0 / (40.0 * f))
        return dt

    def theta_for(self, dt: float) -> float:
        if self.bending == "implicit":
            return 1.0
        if self.bending == "explicit":
            return 0.0
        return 0.0 if dt <= 0.8 * self.explicit_bending_dt() else 1.0

    def check_dt(self, dt: float) -> None:
        """Refuse (or, with ``allow_unstable``, flag) a step above the stability bound."""
        if not (dt > 0 and math.isfinite(dt)):
            raise RodwarpError(f"time step must be a positive number, got {dt}")
        bound = self.max_stable_dt()
        if dt > bound:
            msg = (f"time step {dt:.3g} s exceeds this scene's stability bound {bound:.3g} s "
                   f"({self._bound_reason()}); use dt <= {bound:.3g} s")
            if not self.allow_unstable:
                raise RodwarpError(msg + " or allow_unstable=True")
            warnings.warn(msg, stacklevel=3)

    def _bound_reason(self) -> str:
        if self.bending == "explicit" and self.explicit_bending_dt() < self.contact_dt():
            return "explicit bending, 2/omega_max"
        return "contact resolution, d_min / characteristic speed"

    def _sweeps(self, state_in, state_out, n_contacts, nplanes, pn, pv, pm, fdt, beta, max_push, implicit):
        """Gauss-Seidel sweeps as separate launches (coloured contacts; the GPU path)."""
        m = self.model
        dev = m.device
        N = m.n_rods
        n_active = int(self._n_active.numpy()[0]) if nplanes else 0
        used = 0
        for it in range(self.iterations):
            measure = it == self.iterations - 1 or (self.tolerance > 0 and it % 2 == 1)
            if measure:
                self._residual.zero_()
                self._sresidual.zero_()
            if n_contacts:
                args = [state_out.contact_seg, m.seg_vertex, state_out.contact_st, state_out.contact_normal,
                        state_out.contact_gap, m.inv_mass, wp.float64(m.mu), fdt, beta, max_push,
                        state_out.contact_impulse, state_out.v, self._residual]
                if self.coloring:
                    for c0, c1 in self._color_ranges:
                        self._launch("friction", friction.solve_rod_contacts, dim=c1 - c0, device=dev,
                                     inputs=[self._color_ids[c0:c1], 1, *args])
                else:
                    self._launch("friction", friction.solve_rod_contacts, dim=n_contacts, device=dev,
                                 inputs=[self._color_ids, 0, *args])
            if n_active:
                self._launch("friction", friction.solve_plane_contacts, dim=n_active, device=dev, inputs=[
                    self._active, m.inv_mass, pn, pv, pm, nplanes, self._plane_gap, fdt, beta, max_push,
                    state_out.plane_impulse, state_out.v, self._residual])
            self._launch("elastics", elastics.rod_projection, dim=N, device=dev, inputs=[
                m.rod_start, state_in.x, m.inv_mass, m.rest_length, fdt, implicit, self._bcoef, self._btarget,
                self._bdiag, self._boff1, self._boff2, self._blam, self._rhs, self._dlam,
                m.compliance, self._sdir, self._diag, self._off1, self._lam, self._rhs_scalar(), state_out.v,
                self._sresidual])
            used = it + 1
            if measure and self.tolerance > 0 and it < self.iterations - 1:
                if (self._residual.numpy()[0] < self.tolerance
                        and self._sresidual.numpy()[0] < self.length_tolerance):
                    break
        return float(self._residual.numpy()[0]), float(self._sresidual.numpy()[0]), used

    # ------------------------------------------------------------------ profiling
    def _launch(self, stage: str, kernel, **kw) -> None:
        if self.timings is None:
            wp.launch(kernel, **kw)
            return
        wp.synchronize_device(self.model.device)
        t = time.perf_counter()
        wp.launch(kernel, **kw)
        wp.synchronize_device(self.model.device)
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t

    def reset_timings(self) -> None:
        """Start (or restart) accumulating kernel time per stage in ``self.timings`` (s)."""
        self.timings = {}

    # ------------------------------------------------------------------ buffers
    def _grow(self, cap: int) -> None:
        d = self.model.device
        self._cap = cap
        self._raw_seg = wp.zeros(cap, dtype=wp.vec2i, device=d)
        self._raw_key = wp.zeros(2 * cap, dtype=wp.int64, device=d)
        self._raw_st = wp.zeros(cap, dtype=wp.vec2d, device=d)
        self._raw_normal = wp.zeros(cap, dtype=wp.vec3d, device=d)
        self._raw_gap = wp.zeros(cap, dtype=wp.float64, device=d)
        self._order = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._color = wp.zeros(cap, dtype=wp.int32, device=d)
        self._color_ids = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._color_keys = wp.zeros(2 * cap, dtype=wp.int32, device=d)
        self._gap_check = wp.zeros(cap, dtype=wp.float64, device=d)

    # ------------------------------------------------------------------ step
    def step(self, state_in: State, state_out: State, dt: float, *, check: bool = True) -> StepInfo:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out``.

        Raises
        ------
        RodwarpError
            ``dt`` above the stability bound (unless ``allow_unstable``).
        SimulationBlowUp
            Non-finite or runaway velocities, or rods overlapping deeper than
            ``penetration_limit`` diameters; ``state_in`` is left untouched.
        """
        m = self.model
        dev = m.device
        if check:
            self.check_dt(dt)
            if self._v_elastic is None:
                e = self.energy(state_in)
                self._v_elastic = math.sqrt(2.0 * (e["bending"] + e["stretching"]) / m.total_mass())
        theta = self.theta_for(dt)
        fdt = wp.float64(dt)
        V, N = m.n_vertices, m.n_rods
        state_out.ensure_plane_storage()
        nplanes = len(m.planes)
        if self._plane_gap.shape[0] != V * max(nplanes, 1):
            self._plane_gap = wp.zeros(V * max(nplanes, 1), dtype=wp.float64, device=dev)

        if m.curved:
            self._launch("elastics", elastics.rest_curvature_targets, dim=V, device=dev, inputs=[
                m.rod_start, m.vertex_rod, state_in.x, m.rest_x, m.rest_kappa, self._btarget])
        self._launch("elastics", elastics.velocity_predictor, dim=N, device=dev, inputs=[
            m.rod_start, state_in.x, state_in.v, m.mass, m.inv_mass, m.rest_length, m.bend_stiffness,
            wp.vec3d(*m.gravity), wp.float64(m.damping), fdt, int(theta == 0.0), self._btarget, state_out.v])

        self._scalar.zero_()
        self._launch("checks", broadphase.max_speed, dim=V, device=dev, inputs=[state_out.v, self._scalar])
        sc = self._scalar.numpy()
        if sc[1] != 0.0:
            raise self._blowup(state_in, dt, theta, "non-finite velocity after the elastic predictor")
        vmax = float(sc[0])

        n_contacts = self._detect(state_in, state_out, vmax, dt) if m.rod_contacts and m.n_segments > 1 else 0
        state_out.contact_count = n_contacts

        ws = wp.float64(self.warm_start)
        if n_contacts:
            self._launch("narrowphase", contacts.warm_start_rod_contacts, dim=n_contacts, device=dev, inputs=[
                n_contacts, state_out.contact_key, state_out.contact_normal, state_in.contact_count,
                state_in.contact_key, state_in.contact_impulse, ws, state_out.contact_impulse])
            self._launch("friction", friction.apply_rod_impulses, dim=n_contacts, device=dev, inputs=[
                n_contacts, state_out.contact_seg, m.seg_vertex, state_out.contact_st, m.inv_mass,
                state_out.contact_impulse, state_out.v])
            if self.coloring:
                self._color_contacts(state_out, n_contacts)

        normals, offsets, pvel, mus = m.plane_kinematics(state_in.time, dt)
        pn = wp.array(normals, dtype=wp.vec3d, device=dev)
        pv = wp.array(pvel, dtype=wp.vec3d, device=dev)
        pm = wp.array(mus, dtype=wp.float64, device=dev)
        self._n_active.zero_()
        if nplanes:
            po = wp.array(offsets, dtype=wp.float64, device=dev)
            state_out.plane_impulse.assign(state_in.plane_impulse)
            self._launch("friction", friction.prepare_plane_contacts, dim=V, device=dev, inputs=[
                state_in.x, state_out.v, m.vertex_rod, m.rod_radius, m.inv_mass, pn, po, pv, nplanes,
                wp.float64(m.contact_distance), fdt, ws, self._plane_gap, state_out.plane_impulse, state_out.v,
                self._active, self._n_active])

        self._lam.zero_()
        self._blam.zero_()
        if theta != 0.0 and self._bfactor_dt != dt:
            self._launch("elastics", elastics.bending_factor, dim=N, device=dev, inputs=[
                m.rod_start, m.inv_mass, m.rest_length, m.bend_stiffness, fdt, self._bcoef, self._bdiag, self._boff1,
                self._boff2])
            self._bfactor_dt = dt
        self._launch("elastics", elastics.stretch_factor, dim=N, device=dev, inputs=[
            m.rod_start, state_in.x, m.inv_mass, m.compliance, fdt, self._sdir, self._diag, self._off1])
        beta = wp.float64(self.baumgarte)
        max_push = wp.float64(max(self.characteristic_speed(), 1e-3))
        implicit = int(theta != 0.0)
        if self.fused:
            self._launch("solve", solve.gauss_seidel_sequential, dim=1, device=dev, inputs=[
                self.iterations, wp.float64(self.tolerance), wp.float64(self.length_tolerance), fdt, beta, max_push,
                m.inv_mass, n_contacts, state_out.contact_seg, m.seg_vertex, state_out.contact_st,
                state_out.contact_normal, state_out.contact_gap, wp.float64(m.mu), state_out.contact_impulse,
                self._n_active, self._active, pn, pv, pm, nplanes, self._plane_gap, state_out.plane_impulse,
                N, m.rod_start, state_in.x, m.rest_length, implicit, self._bcoef, self._btarget, self._bdiag, self._boff1,
                self._boff2, self._blam, self._rhs, self._dlam, m.compliance, self._sdir, self._diag, self._off1,
                self._lam, self._rhs_scalar(), state_out.v, self._solve_out])
            res, sres, used = (float(x) for x in self._solve_out.numpy())
            used = int(used)
        else:
            res, sres, used = self._sweeps(state_in, state_out, n_contacts, nplanes, pn, pv, pm, fdt, beta, max_push,
                                           implicit)

        self._launch("elastics", elastics.integrate_positions, dim=V, device=dev, inputs=[state_in.x, state_out.v, fdt, state_out.x])
        state_out.time = state_in.time + dt
        state_out.step_index = state_in.step_index + 1

        self._scalar.zero_()
        self._launch("checks", broadphase.max_speed, dim=V, device=dev, inputs=[state_out.v, self._scalar])
        if n_contacts:
            self._launch("checks", contacts.contact_overlap, dim=n_contacts, device=dev, inputs=[
                n_contacts, state_out.contact_seg, m.seg_vertex, m.vertex_rod, m.rod_radius, state_out.x,
                self._gap_check, self._scalar[2:3]])
        sc = self._scalar.numpy()
        vmax_out = float(sc[0])
        if check:
            if sc[1] != 0.0:
                raise self._blowup(state_in, dt, theta, "non-finite velocity")
            if vmax_out > self.speed_limit:
                raise self._blowup(state_in, dt, theta, f"speed {vmax_out:.3g} m/s above the limit {self.speed_limit:.3g} m/s")
            depth = float(sc[2])
            if depth > self.penetration_limit * m.min_diameter:
                raise self._blowup(state_in, dt, theta, f"rods overlap by {depth / m.min_diameter:.2f} d")
            if self.energy_check_every and state_out.step_index % self.energy_check_every == 0:
                self._check_energy(state_in, state_out, dt, theta)
        info = StepInfo(state_out.step_index, state_out.time, dt, used, n_contacts,
                        float(res), float(sres), vmax_out, theta)
        self.last_info = info
        return info

    def _check_energy(self, state_in: State, state_out: State, dt: float, theta: float) -> None:
        """Energy-jump test: kinetic + elastic energy may not grow 4x between checks beyond
        what the scene can supply (all mass at the characteristic speed)."""
        e = self.energy(state_out)
        mech = e["kinetic"] + e["bending"] + e["stretching"]
        floor = 0.5 * self.model.total_mass() * self.characteristic_speed() ** 2
        prev = self._last_mech
        self._last_mech = mech
        if not math.isfinite(mech):
            raise self._blowup(state_in, dt, theta, "non-finite energy")
        if prev is not None and mech > 4.0 * prev + floor:
            raise self._blowup(state_in, dt, theta,
                               f"energy jump from {prev:.3g} J to {mech:.3g} J within {self.energy_check_every} steps")

    def _rhs_scalar(self):
        if not hasattr(self, "_srhs") or self._srhs.shape[0] != self.model.n_vertices:
            self._srhs = wp.zeros(self.model.n_vertices, dtype=wp.float64, device=self.model.device)
        return self._srhs

    @property
    def speed_limit(self) -> float:
        if self._speed_limit is not None:
            return self._speed_limit
        return 20.0 * (self.characteristic_speed() + (self._v_elastic or 0.0))

    def _blowup(self, state_in: State, dt: float, theta: float, what: str) -> SimulationBlowUp:
        step = state_in.step_index + 1
        t = state_in.time + dt
        eb = self.explicit_bending_dt()
        if theta == 0.0 and dt > eb:
            cause = f"explicit bending at dt = {dt:.3g} s above its bound {eb:.3g} s; use bending='implicit' or a smaller step"
        elif "overlap" in what:
            cause = (f"contacts under-resolved (tunnelling or too few iterations: {self.iterations}); "
                     f"lower dt (now {dt:.3g} s, contact bound {self.contact_dt():.3g} s) or raise iterations")
        else:
            cause = f"step {dt:.3g} s too large for this scene (bound {self.max_stable_dt():.3g} s) or too few iterations"
        return SimulationBlowUp(f"simulation blew up at step {step} (t = {t:.6g} s): {what}; likely cause: {cause}",
                                step=step, time=t, cause=cause)

    # ------------------------------------------------------------------ contacts
    def _detect(self, state_in: State, state_out: State, vmax: float, dt: float) -> int:
        m = self.model
        dev = m.device
        S = m.n_segments
        base = m.contact_distance
        # speculative reach of this step; the pair list is rebuilt when it no longer covers it
        need = base + 2.0 * vmax * dt
        rebuild = self._pairs_n is None or need > self._pairs_margin
        if not rebuild:
            self._scalar.zero_()
            self._launch("broadphase", contacts.max_displacement, dim=m.n_vertices, device=dev,
                      inputs=[state_in.x, self._x_build, self._scalar])
            moved = float(self._scalar.numpy()[0])
            rebuild = 2.0 * moved + need > self._pairs_margin
        if rebuild:
            self._build_pairs(state_in, need)
        n_pairs = self._pairs_n
        while True:
            self._count.zero_()
            if n_pairs:
                self._launch("narrowphase", contacts.narrowphase_pairs, dim=n_pairs, device=dev, inputs=[
                    self._pairs, n_pairs, S, m.seg_vertex, m.vertex_rod, m.rod_radius, state_in.x, state_out.v,
                    wp.float64(base), wp.float64(dt), self._cap, self._count,
                    self._raw_seg, self._raw_key, self._raw_st, self._raw_normal, self._raw_gap])
            n = int(self._count.numpy()[0])
            if n <= self._cap:
                break
            self._grow(2 * n)
        if state_out.contact_capacity < max(n, 1):
            state_out.allocate_contacts(2 * n)
        if n == 0:
            return 0
        self._launch("narrowphase", contacts.iota, dim=n, device=dev, inputs=[self._order])
        t0 = time.perf_counter() if self.timings is not None else 0.0
        wp.utils.radix_sort_pairs(self._raw_key, self._order, n)
        if self.timings is not None:
            self.timings["narrowphase"] = self.timings.get("narrowphase", 0.0) + time.perf_counter() - t0
        wp.copy(state_out.contact_key, self._raw_key, count=n)
        self._launch("narrowphase", contacts.gather_contacts, dim=n, device=dev, inputs=[
            self._order, n, self._raw_seg, self._raw_st, self._raw_normal, self._raw_gap,
            state_out.contact_seg, state_out.contact_st, state_out.contact_normal, state_out.contact_gap])
        return n

    def _build_pairs(self, state: State, need: float) -> None:
        """Broadphase: candidate segment pairs within reach + skin (a Verlet list)."""
        m = self.model
        dev = m.device
        S = m.n_segments
        self._launch("broadphase", broadphase.segment_midpoints, dim=S, device=dev, inputs=[m.seg_vertex, state.x, self._mid])
        hmax = float(m.rest_length_np.max())
        rmax = float(m.radius_np.max())
        margin = need + self.skin
        query = (hmax + 2.0 * rmax + margin) * 1.0001 + 1e-6
        if self._grid is None:
            self._grid = wp.HashGrid(128, 128, 128, device=dev)
        t0 = time.perf_counter() if self.timings is not None else 0.0
        self._grid.build(self._mid, query)
        if self.timings is not None:
            self.timings["broadphase"] = self.timings.get("broadphase", 0.0) + time.perf_counter() - t0
        while True:
            self._count.zero_()
            self._launch("broadphase", contacts.find_candidate_pairs, dim=S, device=dev, inputs=[
                self._grid.id, self._mid, m.seg_vertex, m.vertex_rod, m.rod_radius, state.x, float(query),
                wp.float64(margin), self._pairs_cap, self._count, self._pairs])
            n = int(self._count.numpy()[0])
            if n <= self._pairs_cap:
                break
            self._pairs_cap = 2 * n
            self._pairs = wp.zeros(self._pairs_cap, dtype=wp.vec2i, device=dev)
        self._pairs_n = n
        self._pairs_margin = margin
        wp.copy(self._x_build, state.x)
        self.pair_builds += 1

    def _color_contacts(self, state: State, n: int) -> None:
        """Partition contacts into independent sets (no shared vertex) for race-free GS."""
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
                      inputs=[n, state.contact_seg, m.seg_vertex, self._color, owner])
            self._launch("friction", friction.color_commit, dim=n, device=dev,
                      inputs=[n, state.contact_seg, m.seg_vertex, rnd, owner, self._color, remaining])
            rnd += 1
            if int(remaining.numpy()[0]) == 0:
                break
        self.colors_used = rnd
        wp.copy(self._color_keys, self._color, count=n)
        self._launch("narrowphase", contacts.iota, dim=n, device=dev, inputs=[self._color_ids])
        wp.utils.radix_sort_pairs(self._color_keys, self._color_ids, n)
        counts = np.bincount(self._color.numpy()[:n], minlength=rnd)
        edges = np.concatenate([[0], np.cumsum(counts)])
        self._color_ranges = [(int(edges[i]), int(edges[i + 1])) for i in range(rnd) if counts[i] > 0]

    # ------------------------------------------------------------------ diagnostics
    def _targets_for(self, state: State):
        m = self.model
        if not m.curved:
            return self._btarget
        t = wp.zeros(m.n_vertices, dtype=wp.vec3d, device=m.device)
        wp.launch(elastics.rest_curvature_targets, dim=m.n_vertices, device=m.device, inputs=[
            m.rod_start, m.vertex_rod, state.x, m.rest_x, m.rest_kappa, t])
        return t

    def energy(self, state: State) -> dict:
        """Kinetic, potential (gravity), bending and stretching energy (J) of ``state``."""
        m = self.model
        out = wp.zeros(4, dtype=wp.float64, device=m.device)
        self._launch("checks", elastics.elastic_energy, dim=m.n_rods, device=m.device, inputs=[
            m.rod_start, state.x, state.v, m.mass, m.rest_length, m.compliance, m.bend_stiffness,
            self._targets_for(state), wp.vec3d(*m.gravity), out])
        k, p, b, s = (float(x) for x in out.numpy())
        return {"kinetic": k, "potential": p, "bending": b, "stretching": s, "total": k + p + b + s}


def run(solver: RodSolver, state: State, duration: float, dt: float, *, callback=None, every: int = 1) -> State:
    """Step ``state`` forward by ``duration`` seconds with step ``dt``; returns the final state.

    Two states are ping-ponged; ``callback(state, info)`` is called every ``every`` steps
    with the state just written.  The input ``state`` object is updated in place at the end.
    """
    n = int(round(duration / dt))
    a = state
    b = State(solver.model, a.contact_capacity)
    b.copy_from(a)
    for k in range(n):
        info = solver.step(a, b, dt)
        a, b = b, a
        if callback is not None and (k + 1) % every == 0:
            callback(a, info)
    if a is not state:
        state.copy_from(a)
    return state
