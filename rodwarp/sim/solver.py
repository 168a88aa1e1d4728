"""Projected Gauss-Seidel solver: implicit elastics, contact at the rods' surfaces under the model's law.

One step of :meth:`RodSolver.step` (all on the model's device), one method per phase:

1. ``_predict``: frames at the start of the step (edge tangents, reference twists, the rest
   curvature of curved rods in the current material frame) and the velocity predictor, one
   thread per rod: damping, gravity, applied torques and, for symplectic (explicit) bending,
   the bending force;
2. ``_step_params``: the step's scalars, the contact law's tag and parameters among them;
3. ``_prepare_rod_contacts``: the rod-rod contact points that :meth:`RodSolver.collide` found
   at the start-of-step positions (:class:`~rodwarp.sim.contacts.ContactPoints`: speculative,
   sorted), framed and warm-started (coloured on a GPU);
4. ``_prepare_wall_contacts``: the wall contacts of the walls in place, found, warm-started and
   framed in one fused pass per rod;
5. ``_factor_rods``: the rods' bending, twist and edge-length systems factored;
6. ``_solve``: ``iterations`` Gauss-Seidel sweeps over rod-rod contacts, wall contacts and
   exact per-rod solves of bending, twist and edge-length constraints; every block uses the
   same mass metric, so the converged step is implicit Euler under the contact law and its
   fixed point is the static equilibrium;
7. ``_advance``: x' = x + dt v', overlaps projected out (laws that ask it), theta' = theta +
   dt omega', directors transported with their edges;
8. ``_check_step``: fastest speed and deepest overlap; a blow-up raises before the contacts
   commit.

As in Newton, contacts come from a collide step and are passed to the step::

    contacts = solver.collide(state_in, control, dt, contacts)
    solver.step(state_in, state_out, control, contacts, dt)

``state_in`` and the contacts' last impulses are never modified by a step that fails its
checks, so a retry starts from the last good state (bit for bit).
"""

from __future__ import annotations

import math
import time
import warnings
from dataclasses import dataclass

import warp as wp

from rodwarp._warp import LaunchCache
from rodwarp.errors import RodwarpError
from rodwarp.kernels import broadphase, contact_laws, elastics, frames, friction, narrowphase, solve, wall_contacts
from rodwarp.kernels.structs import ContactFrame, LawParams, RodFactors, StepParams
from rodwarp.sim._bounds import STEPS_PER_PERIOD, StepBounds
from rodwarp.sim._diagnostics import SolverChecks
from rodwarp.sim._launches import SolveLaunches
from rodwarp.sim.contacts import ContactPipeline, ContactPoints
from rodwarp.sim.law_exact import bounce_speed
from rodwarp.arguments import instance, optional_real, real, whole
from rodwarp.sim._limits import MAX_LENGTH_M, MAX_SPEED
from rodwarp.sim.model import Model
from rodwarp.sim.state import State

#: most Gauss-Seidel sweeps (of velocities or positions) per step, as ``rodwarp simulate --iterations``
MAX_SWEEPS = 100_000
#: most steps :func:`run` takes (1e9 steps of the smallest scene take weeks on a CPU core)
MAX_STEPS = 1e9


def _check_settings(*, iterations, tolerance, warm_start, baumgarte, slop, relax, position_sweeps,
                    position_tolerance, penetration_limit, speed_limit, energy_check_every, skin,
                    steps_per_period) -> None:
    """The ranges of :class:`RodSolver`'s settings (their meaning and units are in its docstring)."""
    whole("iterations", iterations, ge=1, le=MAX_SWEEPS)
    real("tolerance", tolerance, ge=0, le=MAX_SPEED, unit="m/s", hint="0 always runs every sweep")
    for name, v in (("warm_start", warm_start), ("baumgarte", baumgarte)):
        real(name, v, ge=0, le=1, hint="a fraction")
    for name, v in (("slop", slop), ("position_tolerance", position_tolerance)):
        real(name, v, ge=0, le=1, hint="in diameters of the thinnest rod")
    real("relax", relax, gt=0, lt=2, hint="over-relaxation converges only in (0, 2); 1 is plain Gauss-Seidel")
    whole("position_sweeps", position_sweeps, ge=0, le=MAX_SWEEPS)
    real("penetration_limit", penetration_limit, gt=0, le=10, hint="in diameters of the thinnest rod")
    optional_real("speed_limit", speed_limit, gt=0, le=1e6, unit="m/s", hint="leave it None for the default")
    whole("energy_check_every", energy_check_every, ge=0, le=int(MAX_STEPS))
    optional_real("skin", skin, gt=0, le=MAX_LENGTH_M, unit="m", hint="leave it None for the default")
    real("steps_per_period", steps_per_period, ge=1, le=1e6)


@dataclass
class StepInfo:
    """Diagnostics of one step.

    Attributes
    ----------
    iterations : int
        Gauss-Seidel sweeps actually run.
    n_contacts : int
        Contact points solved (rod-rod, speculative ones included; docs/physics.md,
        "Contact"), not the contacts of the packing (:func:`rodwarp.sim.rod_contacts`).
    max_speed : float
        Fastest vertex speed at the end of the step (m/s).
    theta : float
        Bending integration of the step: 0 explicit (symplectic), 1 implicit Euler.
    contact_residual : float
        Largest velocity change (m/s) that any contact caused in the last Gauss-Seidel sweep;
        0 for a fully converged solve.
    stretch_residual : float
        Largest edge-length error (m) before the last stretch projection.
    max_overlap : float
        Deepest rod-rod overlap at the end of the step (m); 0 when no rods touch.
    position_passes : int
        Post-stabilisation sweeps run (they stop at ``position_tolerance``).
    """

    step: int
    time: float
    dt: float
    iterations: int
    n_contacts: int
    contact_residual: float
    stretch_residual: float
    max_speed: float
    theta: float
    max_overlap: float = 0.0
    position_passes: int = 0


class RodSolver(StepBounds, SolverChecks, SolveLaunches):
    """Advance a :class:`~rodwarp.sim.model.Model` from ``state_in`` to ``state_out``.

    The step bounds, the default and adaptive steps and the step guard (``step_bound``,
    ``max_stable_dt``, ``default_dt``, ``adaptive_dt``, ``check_dt``, ...) come from
    :class:`~rodwarp.sim._bounds.StepBounds`; docs/physics.md describes them.

    Parameters
    ----------
    model : Model
        The scene.
    iterations : int
        Most Gauss-Seidel sweeps per step (contacts, walls, bending, twist, stretching each).
    tolerance : float
        Stop sweeping early once a sweep changes no contact velocity by more than this (m/s;
        1e-5 m/s: 10 um of drift per second) and no edge length is off by more than 1e-6 of the
        shortest edge; 0 always runs ``iterations`` sweeps. Checked every second sweep.
    bending : {"auto", "implicit", "explicit"}
        Bending integration. ``auto`` bends implicitly (implicit Euler) whenever rods can
        touch something (rod contacts, or a wall in place): symplectic Euler with inelastic
        contacts pumps energy into bending modes (docs/physics.md). In a contact-free scene it
        uses symplectic (explicit) bending when the step is below 0.8 of its numerical
        stability bound 2 / omega_max, which conserves energy, and implicit Euler above it.
        Curved rods always bend implicitly (their bending is coupled to twist).
    coloring : {"auto", "on", "off"}
        Colour rod-rod contacts so that each colour can be solved in parallel without data
        races. ``auto`` colours on CUDA only; a CPU launch is already sequential.
    warm_start : float
        Fraction of last step's impulses reused (0 disables warm starting).
    baumgarte : float
        Fraction of an overlap (beyond the slop) removed per position sweep of the
        post-stabilisation.
    position_sweeps : int
        Most Gauss-Seidel sweeps of the post-stabilisation that removes overlaps from the
        end-of-step positions (0: none, overlaps are then only prevented, never undone).
        Parallel devices run them all (stopping would need a read-back per sweep).
    position_tolerance : float
        The post-stabilisation stops after a sweep that found no overlap deeper than this, in
        diameters of the thinnest rod (0.015: halfway between the slop and the adaptive
        step's overlap target, 0.02, so that the overlaps left do not shrink the adaptive step;
        a shaken rigid pile stops after one or two sweeps).
    slop : float
        Overlap left alone, in units of the smallest diameter: a resting contact is not
        pushed apart, so its velocity problem repeats from step to step, warm starting holds
        and the sweep converges.
    relax : float
        Over-relaxation of each contact's impulse update (successive over-relaxation; 1 is
        plain Gauss-Seidel), the relaxed impulse projected back onto the friction cone.
    penetration_limit : float
        A step whose deepest rod overlap exceeds this fraction of the smallest diameter
        raises :class:`SimulationBlowUp`.
    speed_limit : float, optional
        Speeds above this (m/s) are treated as a blow-up; default 20 x the scene's
        characteristic speed (free fall over the scene height, drive speed, initial speeds
        and the speed the initial elastic energy could give all rods).
    allow_unstable : bool
        Accept a step above the step bound with a warning instead of an error.
    energy_check_every : int
        Steps between energy-jump checks (0 disables them).
    skin : float, optional
        Extra reach of the broadphase pair list (m); a segment's pairs are found again when it
        has moved by a quarter of it, the whole list when 30% of the segments have. Default
        d_min + min(h_max, 20 d_min) / 5 (measured knees, benchmarks).
    steps_per_period : float
        The fewest steps the default and adaptive steps take per period of a drive (40).
    """

    def __init__(
        self,
        model: Model,
        *,
        iterations: int = 40,
        tolerance: float = 1e-5,
        bending: str = "auto",
        coloring: str = "auto",
        warm_start: float = 1.0,
        baumgarte: float = 0.8,
        slop: float = 0.01,
        relax: float = 1.5,
        position_sweeps: int = 16,
        position_tolerance: float = 0.015,
        penetration_limit: float = 0.25,
        speed_limit: float | None = None,
        allow_unstable: bool = False,
        energy_check_every: int = 10,
        skin: float | None = None,
        steps_per_period: float = STEPS_PER_PERIOD,
    ):
        instance("model", model, Model, "a Model (ModelBuilder(rods, ...).finalize())")
        _check_settings(iterations=iterations, tolerance=tolerance, warm_start=warm_start, baumgarte=baumgarte,
                        slop=slop, relax=relax, position_sweeps=position_sweeps,
                        position_tolerance=position_tolerance, penetration_limit=penetration_limit,
                        speed_limit=speed_limit, energy_check_every=energy_check_every, skin=skin,
                        steps_per_period=steps_per_period)
        if bending not in ("auto", "implicit", "explicit"):
            raise RodwarpError(f"bending must be auto, implicit or explicit, got '{bending}'")
        if bending == "explicit" and model.curved:
            raise RodwarpError("explicit bending is not available for curved rods (their bending is coupled to "
                               "twist); use bending='implicit' or 'auto'")
        if coloring not in ("auto", "on", "off"):
            raise RodwarpError(f"coloring must be auto, on or off, got '{coloring}'")
        self.model = model
        self.steps_per_period = float(steps_per_period)
        self.iterations = int(iterations)
        self.tolerance = float(tolerance)
        self.length_tolerance = 1e-6 * float(model.rest_length_np[model.rest_length_np > 0].min())
        self.bending = bending
        self.coloring = coloring == "on" or (coloring == "auto" and wp.get_device(model.device).is_cuda)
        self.warm_start = float(warm_start)
        self.baumgarte = float(baumgarte)
        self.slop = float(slop)
        self.relax = float(relax)
        self.guard_factor = 2.0
        self.penetration_limit = float(penetration_limit)
        self.allow_unstable = bool(allow_unstable)
        self._speed_limit = speed_limit
        self._v_elastic = None
        self._eb_dt = None
        self._char_speed: dict = {}
        self._last_mech = None
        self.energy_check_every = int(energy_check_every)
        self._default_control = None
        self._launches = LaunchCache()
        self._warned_explicit = False
        # one StepParams for the solver's life, its fields set every step (recorded launches)
        self._params = StepParams()
        law = model.contact_law
        self._law_tag = law.tag
        self._law_params = LawParams(*law.device_params(), *[0.0] * (8 - len(law.device_params())))
        # Newton restitution of the exact law (0: off, the law as without the option); the
        # velocities before the step's contact impulses, rigid rods as bodies, when it is on
        self._restitution = float(getattr(law, "restitution", 0.0) or 0.0)
        self._g_mag = float(math.sqrt(sum(float(g) ** 2 for g in model.gravity)))
        self._v_before = self._spin_before = self._axial_before = None
        contact_laws.seal()  # the kernels built from here on dispatch over the laws registered now
        d = model.device
        V = model.n_vertices
        f = self.factors = RodFactors()
        f.implicit_bending = 1
        for name, dtype in (("bend_stencil", wp.vec4d), ("bend_target", wp.vec3d), ("bend_inv_pivot", wp.float64),
                            ("bend_lower1", wp.float64), ("bend_lower2", wp.float64), ("bend_lambda", wp.vec3d),
                            ("bend_rhs", wp.vec3d), ("bend_dlambda", wp.vec3d), ("stretch_dir", wp.vec3d),
                            ("stretch_inv_pivot", wp.float64), ("stretch_lower", wp.float64),
                            ("stretch_lambda", wp.float64), ("stretch_rhs", wp.float64), ("axial", wp.float64),
                            ("tangent", wp.vec3d), ("ref_twist", wp.float64), ("twist_inv_pivot", wp.float64),
                            ("twist_lower", wp.float64), ("twist_lambda", wp.float64), ("twist_rhs", wp.float64),
                            ("curved_coupling", wp.vec3d), ("curved_lambda", wp.vec4d), ("curved_rhs", wp.vec4d),
                            ("curved_dlambda", wp.vec4d)):
            setattr(f, name, wp.zeros(V, dtype=dtype, device=d))
        Vc = V if model.curved else 1
        for name in ("curved_pivot", "curved_inv_pivot", "curved_lower1", "curved_lower2"):
            setattr(f, name, wp.zeros(Vc, dtype=wp.mat44d, device=d))
        self._bfactor_dt = None
        self._scalar = wp.zeros(4, dtype=wp.float64, device=d)
        self._energy_out = wp.zeros(5, dtype=wp.float64, device=d)
        self._residual = wp.zeros(1, dtype=wp.float64, device=d)
        self._sresidual = wp.zeros(1, dtype=wp.float64, device=d)
        if skin is None:
            # measured knees: d + h/5 for ten-vertex rods; capped at 20 d for long (rigid) segments,
            # whose candidate list would otherwise hold every rod within a fifth of a length
            dmin = model.min_diameter
            skin = dmin + 0.2 * min(float(model.rest_length_np.max()), 20.0 * dmin)
        self.collision = ContactPipeline(model, skin, self._launch, lambda: self.timings)
        self._own_contacts: ContactPoints | None = None  # for step() called without contacts
        # collide()'s copy of the velocity predictor (the speculative reach), and the zero rest
        # curvature it reads: explicit bending, the only bending in the predictor, is for
        # straight rods, whose targets are zero
        self._v_pred = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._spin_pred = wp.zeros(V, dtype=wp.float64, device=d)
        self._zero_target = wp.zeros(V, dtype=wp.vec3d, device=d)
        self._wall_gap = wp.zeros(V * max(len(model.walls), 1), dtype=wp.float64, device=d)
        self._wall_normal = wp.zeros(V * max(len(model.walls), 1), dtype=wp.vec3d, device=d)
        self._active = wp.zeros(max(model.n_rods, 1), dtype=wp.int32, device=d)
        self._n_active = wp.zeros(1, dtype=wp.int32, device=d)
        self._wall_span = wp.zeros(max(model.n_rods, 1), dtype=wp.vec2i, device=d)
        self._n_wall_frames = wp.zeros(1, dtype=wp.int32, device=d)
        self._wall_key = wp.zeros(max(16, 2 * model.n_rods), dtype=wp.int32, device=d)
        self._wall_frames = wp.empty(max(16, 2 * model.n_rods), dtype=ContactFrame, device=d)
        self._solve_out = wp.zeros(3, dtype=wp.float64, device=d)
        self._no_gaps = wp.zeros(0, dtype=wp.float64, device=d)  # the step's overlap check keeps no per-contact gaps
        self._last_solve = None
        self._proj_out = wp.zeros(2, dtype=wp.float64, device=d)
        self.position_sweeps = int(position_sweeps)
        self.position_tolerance = float(position_tolerance)
        self._frames = wp.empty(max(16, 4 * model.n_segments), dtype=ContactFrame, device=d)
        self._walls_struct = None
        self._walls_key = None
        # sequential devices run the whole solve in one launch (same order, no launch overhead)
        self.fused = (not self.coloring) and not wp.get_device(model.device).is_cuda
        self.last_info: StepInfo | None = None
        # per-stage kernel seconds (elastics, broadphase, narrowphase, friction, checks) when
        # profiling; None (no synchronisation, no overhead) otherwise
        self.timings: dict | None = None

    @property
    def skin(self) -> float:
        return self.collision.skin

    @property
    def pair_builds(self) -> int:
        return self.collision.builds

    @property
    def colors_used(self) -> int:
        return self.collision.colors_used

    def invalidate_pairs(self) -> None:
        """Force the broadphase to rebuild its pair list at the next collide (benchmarks)."""
        self.collision.pairs_n = None

    def contact_points(self, capacity: int = 16) -> ContactPoints:
        """New, empty :class:`~rodwarp.sim.contacts.ContactPoints` for this solver's model
        (room for ``capacity`` points; they grow as needed)."""
        return ContactPoints(self.model, capacity)

    def contacts(self, capacity: int = 16) -> ContactPoints:
        """:meth:`contact_points` (its first name)."""
        return self.contact_points(capacity)

    @property
    def default_contact_points(self) -> ContactPoints:
        """The contact points :meth:`step` collides into and solves when it is given none (their
        warm start carries over from one such step to the next)."""
        if self._own_contacts is None:
            self._own_contacts = self.contact_points()
        return self._own_contacts

    @property
    def default_contacts(self) -> ContactPoints:
        """:attr:`default_contact_points` (its first name)."""
        return self.default_contact_points

    def _control(self, control):
        if control is not None:
            return control
        if self._default_control is None:
            self._default_control = self.model.control()
        return self._default_control

    # ------------------------------------------------------------------ profiling
    def _launch(self, stage: str, kernel, *, dim, device, inputs) -> None:
        if self.timings is None:
            self._launches.launch(kernel, dim, device, inputs)
            return
        wp.synchronize_device(self.model.device)
        t = time.perf_counter()
        self._launches.launch(kernel, dim, device, inputs)
        wp.synchronize_device(self.model.device)
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t

    def reset_timings(self) -> None:
        """Start (or restart) accumulating kernel time per stage in ``self.timings`` (s)."""
        self.timings = {}

    # ------------------------------------------------------------------ step
    def _touching(self, contacts: ContactPoints, control) -> bool:
        """Whether the coming step starts touching something: rod contacts in the last step, or
        a wall in place (it decides the bending integration, :meth:`theta_for`)."""
        return contacts.last.count > 0 or (len(self.model.walls) > 0 and bool(control.walls_in_place()))

    def collide(self, state: State, control=None, dt: float | None = None, contacts: ContactPoints | None = None
                ) -> ContactPoints:
        """Rod-rod contact points of a step of ``dt`` s from ``state``, into ``contacts``.

        The points are speculative: a pair is kept when its gap is below the contact distance
        plus what both segments can close in the step at the velocities of the step's own
        predictor (gravity, damping, explicit bending), so no pair tunnels. They are sorted by
        key, so the visiting order, and the result, are the same on every run and device.

        Parameters
        ----------
        state : State
            The state the step starts from.
        control : Control, optional
            Walls in place, drive and torques (default: every wall in place, no drive).
        dt : float
            The step (s) about to be taken.
        contacts : ContactPoints, optional
            Where to put them (their last step's impulses warm-start the coming step); default
            a new :meth:`contact_points`.

        Returns
        -------
        ContactPoints
            ``contacts``, for :meth:`step`.
        """
        if dt is None or not (dt > 0 and math.isfinite(dt)):
            raise RodwarpError(f"collide needs the coming step dt (s) as a positive number, got {dt}")
        m = self.model
        dev = m.device
        control = self._control(control)
        contacts = self.contact_points() if contacts is None else contacts
        if contacts.model is not m:
            raise RodwarpError("these contacts belong to another model: make them with solver.contact_points()")
        theta = self.theta_for(dt, self._touching(contacts, control))
        self._launch("elastics", elastics.velocity_predictor, dim=m.n_rods, device=dev, inputs=[
            m.arrays, state.rod_state(), self._zero_target, control.torque(), wp.vec3d(*m.gravity),
            wp.float64(m.damping), wp.float64(dt), int(theta == 0.0), self._v_pred, self._spin_pred])
        self._scalar.zero_()
        self._launch("checks", broadphase.max_speed, dim=m.n_vertices, device=dev, inputs=[self._v_pred, self._scalar])
        sc = self._scalar.numpy()
        vmax = float(sc[0]) if sc[1] == 0.0 else math.nan
        contacts.predicted_speed = vmax
        n = 0
        if m.rod_contacts and m.n_segments > 1 and math.isfinite(vmax):
            n = self.collision.detect(state, contacts.next, self._v_pred, vmax, dt)
        contacts.next.count = n
        contacts.collided_for = (id(state), state.step_index, state.time, id(control), dt)
        return contacts

    def step(self, state_in: State, state_out: State, control=None, contacts: ContactPoints | None = None,
             dt: float | None = None, *, check: bool = True) -> StepInfo:
        """Advance ``state_in`` by ``dt`` seconds into ``state_out`` under ``control``, solving
        the ``contacts`` that :meth:`collide` found for this step.

        Parameters
        ----------
        state_in, state_out : State
            Distinct states of this model; ``state_in`` is not modified.
        control : Control, optional
            Walls in place, drive and torques; default: every wall in place, no drive.
        contacts : ContactPoints, optional
            From ``collide(state_in, control, dt, contacts)``; on success their points become
            the last step's (warm start of the next). None: the solver collides itself, with
            contacts of its own.
        dt : float
            Time step (s).

        Raises
        ------
        RodwarpError
            ``dt`` above the step bound (unless ``allow_unstable``), or ``contacts`` not
            collided for this state, control and step.
        SimulationBlowUp
            Non-finite or runaway velocities, or rods overlapping deeper than
            ``penetration_limit`` diameters; ``state_in`` and the contacts' last step are left
            untouched.
        """
        control, contacts = self._step_inputs(state_in, control, contacts, dt, check)
        touching = self._touching(contacts, control)
        theta = self.theta_for(dt, touching)
        if theta == 0.0 and touching and not self._warned_explicit:
            self._warned_explicit = True
            warnings.warn("explicit (symplectic) bending with contacts: inelastic contacts pump energy into the "
                          "rods' bending (docs/physics.md, 'Bending integration'); use bending='auto' or 'implicit'",
                          stacklevel=2)
        cur = contacts.next
        n_contacts = cur.count
        contacts_view = cur.view()
        self._predict(state_in, state_out, control, contacts, dt, theta, check)
        params = self._step_params(control, dt)
        before = self._velocities_before(state_in, state_out) if (n_contacts or self.model.walls) else None
        if n_contacts:
            self._prepare_rod_contacts(state_in, state_out, contacts, contacts_view, params, before)
        walls = self._walls(control, state_in.time, dt)
        wc = self._prepare_wall_contacts(state_in, state_out, contacts, contacts_view, walls, params, before)
        self._factor_rods(state_in, dt, theta)
        res, sres, used = self._solve(state_in, state_out, contacts_view, walls, wc, params)
        passes = self._advance(state_in, state_out, contacts_view, walls, wc, params, dt)
        vmax_out, depth = self._check_step(state_in, state_out, cur, control, dt, theta, check)
        contacts.commit()  # the step passed its checks: its impulses warm-start the next
        info = StepInfo(state_out.step_index, state_out.time, dt, used, n_contacts,
                        float(res), float(sres), vmax_out, theta, max(depth, 0.0), passes)
        self.last_info = info
        return info

    # the phases of a step, in order (each launches on the model's device)
    def _step_inputs(self, state_in: State, control, contacts, dt, check: bool):
        """Phase 0: the step's control and contacts, checked (collided now when none are given);
        the elastic speed of ``state_in`` measured once for the speed limit."""
        if isinstance(contacts, (int, float)):
            raise RodwarpError("step(state_in, state_out, control, contacts, dt): the fourth argument is the "
                               "contacts from solver.collide(...); pass the step as dt=")
        if dt is None:
            raise RodwarpError("step needs a time step dt (s)")
        m = self.model
        control = self._control(control)
        if check and not (dt > 0 and math.isfinite(dt)):
            raise RodwarpError(f"time step must be a positive number, got {dt}")
        if contacts is None:
            contacts = self.collide(state_in, control, dt, self.default_contact_points)
        elif contacts.collided_for != (id(state_in), state_in.step_index, state_in.time, id(control), dt):
            raise RodwarpError("these contacts were not collided for this step: call "
                               "solver.collide(state_in, control, dt, contacts) right before solver.step")
        if check and self._v_elastic is None:
            e = self.energy(state_in)
            self._v_elastic = math.sqrt(2.0 * (e["bending"] + e["stretching"] + e["twist"]) / m.total_mass())
        return control, contacts

    def _predict(self, state_in: State, state_out: State, control, contacts: ContactPoints, dt: float, theta: float,
                 check: bool) -> None:
        """Phase 1: the frames at the start of the step (tangents, reference twists, curved
        rods' targets) and the velocity predictor into ``state_out`` (damping, gravity,
        torques, explicit bending when ``theta`` is 0); the step guard at the predicted speed."""
        m = self.model
        dev = m.device
        f = self.factors
        f.implicit_bending = int(theta != 0.0)
        rs_in = state_in.rod_state()
        self._launch("elastics", frames.step_frames, dim=m.n_rods, device=dev, inputs=[m.arrays, rs_in, f])
        self._launch("elastics", elastics.velocity_predictor, dim=m.n_rods, device=dev, inputs=[
            m.arrays, rs_in, f.bend_target, control.torque(), wp.vec3d(*m.gravity), wp.float64(m.damping),
            wp.float64(dt), int(theta == 0.0), state_out.v, state_out.spin])
        # the predictor's fastest speed was measured by collide (the same kernel on the same input)
        vmax = contacts.predicted_speed
        if not math.isfinite(vmax):
            raise self._blowup(state_in, dt, theta, "non-finite velocity after the elastic predictor", control)
        if check:
            # the guard follows the motion: the bound at the speeds this step starts from
            self.check_dt(dt, control, speed=vmax)

    def _step_params(self, control, dt: float) -> StepParams:
        """Phase 2: the scalars of this step (the solver's one :class:`StepParams`, refilled)."""
        m = self.model
        params = self._params
        params.dt = wp.float64(dt)
        params.mu = wp.float64(m.mu)
        params.beta = wp.float64(self.baumgarte)
        params.slop = wp.float64(self.slop * m.min_diameter)
        params.max_push = wp.float64(max(self.characteristic_speed(control), 1e-3))
        params.contact_distance = wp.float64(m.contact_distance)
        params.warm = wp.float64(self.warm_start)
        params.relax = wp.float64(self.relax)
        params.iterations = self.iterations
        params.tolerance = wp.float64(self.tolerance)
        params.length_tolerance = wp.float64(self.length_tolerance)
        params.law = self._law_tag
        params.law_params = self._law_params
        params.restitution = wp.float64(self._restitution)
        params.bounce_speed = wp.float64(bounce_speed(self._g_mag, dt) if self._restitution > 0 else 0.0)
        return params

    def _velocities_before(self, state_in: State, state_out: State):
        """The velocities at the start of the step (``state_in``'s: before this step's contact
        impulses and its gravity, so that a bounce at e = 1 returns the speed it came with and
        repeated bounces gain nothing), rigid rods as bodies (``rigid_to_body``): what
        restitution measures the approach on. Without restitution, ``state_out``'s arrays (the
        kernels do not read them)."""
        if self._restitution <= 0:
            return state_out.v, state_out.spin
        m = self.model
        if self._v_before is None:
            V = m.n_vertices
            self._v_before = wp.zeros(V, dtype=wp.vec3d, device=m.device)
            self._spin_before = wp.zeros(V, dtype=wp.float64, device=m.device)
            self._axial_before = wp.zeros(V, dtype=wp.float64, device=m.device)
        wp.copy(self._v_before, state_in.v)
        wp.copy(self._spin_before, state_in.spin)
        self._launch("friction", friction.rigid_bodies_to_sweeps, dim=m.n_rods, device=m.device, inputs=[
            m.arrays, self.factors.tangent, self._v_before, self._spin_before, self._axial_before])
        return self._v_before, self._spin_before

    def _prepare_rod_contacts(self, state_in: State, state_out: State, contacts: ContactPoints, contacts_view,
                              params: StepParams, before) -> None:
        """Phase 3: the rod-rod contact points' frames (sides, mobility, tangent basis, normal
        target), their warm-start impulses applied to ``state_out``, and their colours (parallel
        devices). ``before``: :meth:`_velocities_before`."""
        m = self.model
        dev = m.device
        f = self.factors
        last, cur = contacts.last, contacts.next
        n_contacts = cur.count
        if self._frames.shape[0] < n_contacts:
            self._frames = wp.empty(2 * n_contacts, dtype=ContactFrame, device=dev)
        self._launch("friction", friction.prepare_rod_contacts, dim=n_contacts, device=dev, inputs=[
            m.arrays, state_in.x, contacts_view, f.tangent, params, self._frames, *before])
        self.collision.warm_start(last, cur, n_contacts, self.warm_start)
        self._launch("friction", friction.apply_rod_impulses, dim=n_contacts, device=dev, inputs=[
            contacts_view, self._frames, state_in.x, f.tangent, state_out.v, state_out.spin])
        if self.coloring:
            self.collision.color(cur, n_contacts)

    def _prepare_wall_contacts(self, state_in: State, state_out: State, contacts: ContactPoints, contacts_view,
                               walls, params: StepParams, before):
        """Phase 4: the wall contacts within reach of the walls in place, found, warm-started
        and framed in one pass per rod (the frame list grown when it overflows). Returns the
        wall contacts' view."""
        m = self.model
        dev = m.device
        f = self.factors
        last, cur = contacts.last, contacts.next
        wc = self._wall_contacts(cur)
        self._last_solve = (contacts_view, params, walls, wc)
        self._n_active.zero_()
        self._n_wall_frames.zero_()
        if m.walls:
            cur.wall_impulse.assign(last.wall_impulse)
            self._launch("friction", wall_contacts.prepare_wall_contacts, dim=m.n_rods, device=dev, inputs=[
                m.arrays, state_in.x, f.tangent, walls, params, wc, state_out.v, state_out.spin, *before])
            needed = int(self._n_wall_frames.numpy()[0])
            if needed > self._wall_frames.shape[0]:
                # more wall contacts than ever before: grow the frame list and fill it
                self._wall_key = wp.zeros(2 * needed, dtype=wp.int32, device=dev)
                self._wall_frames = wp.empty(2 * needed, dtype=ContactFrame, device=dev)
                wc = self._wall_contacts(cur)
                self._last_solve = (contacts_view, params, walls, wc)
                self._launch("friction", wall_contacts.fill_wall_frames, dim=int(self._n_active.numpy()[0]), device=dev,
                             inputs=[m.arrays, state_in.x, f.tangent, walls, params, wc, *before])
        return wc

    def _factor_rods(self, state_in: State, dt: float, theta: float) -> None:
        """Phase 5: the rods' internal constraints factored for this step (multipliers zeroed;
        bending refactored only when the step changes)."""
        m = self.model
        dev = m.device
        f = self.factors
        fdt = wp.float64(dt)
        f.bend_lambda.zero_()
        f.stretch_lambda.zero_()
        f.twist_lambda.zero_()
        if m.curved:
            f.curved_lambda.zero_()
            self._launch("elastics", elastics.curved_factor, dim=m.n_rods, device=dev, inputs=[m.arrays, fdt, f])
        if theta != 0.0 and self._bfactor_dt != dt:
            self._launch("elastics", elastics.bending_factor, dim=m.n_rods, device=dev, inputs=[m.arrays, fdt, f])
            self._bfactor_dt = dt
        self._launch("elastics", elastics.stretch_twist_factor, dim=m.n_rods, device=dev, inputs=[
            m.arrays, state_in.x, fdt, f])

    def _solve(self, state_in: State, state_out: State, contacts_view, walls, wc, params: StepParams):
        """Phase 6: the Gauss-Seidel sweeps over contacts, walls and rods on ``state_out``'s
        velocities (one launch on a sequential device). Returns (contact residual (m/s),
        stretch residual (m), sweeps run)."""
        m = self.model
        rs_in = state_in.rod_state()
        if self.fused:
            self._launch("solve", solve.gauss_seidel_sequential, dim=1, device=m.device, inputs=[
                m.arrays, rs_in,
                contacts_view, self._frames, walls, wc, self.factors, params, state_out.v, state_out.spin,
                self._solve_out])
            res, sres, used = (float(x) for x in self._solve_out.numpy())
            return res, sres, int(used)
        return self._sweeps(rs_in, state_out, contacts_view, walls, wc, params, len(m.walls))

    def _advance(self, state_in: State, state_out: State, contacts_view, walls, wc, params: StepParams,
                 dt: float) -> int:
        """Phase 7: x' = x + dt v', overlaps projected out when the law asks it, material angles
        and directors carried along; the time advanced. Returns the projection sweeps run."""
        m = self.model
        dev = m.device
        fdt = wp.float64(dt)
        self._launch("elastics", elastics.integrate_positions, dim=m.n_vertices, device=dev,
                     inputs=[state_in.x, state_out.v, fdt, state_out.x])
        passes = 0
        if self.position_sweeps and (contacts_view.count or m.walls) and m.contact_law.projects_overlaps:
            passes = self._project_positions(state_in.rod_state(), state_out, contacts_view, walls, wc, params,
                                             len(m.walls))
        self._launch("elastics", frames.advance_frames, dim=m.n_vertices, device=dev, inputs=[
            m.arrays, state_in.x, state_out.x, state_in.director, state_in.theta, state_out.spin, fdt,
            state_out.director, state_out.theta])
        state_out.time = state_in.time + dt
        state_out.step_index = state_in.step_index + 1
        return passes

    def _check_step(self, state_in: State, state_out: State, cur, control, dt: float, theta: float, check: bool):
        """Phase 8: the fastest speed and deepest rod overlap at the end of the step; with
        ``check``, a blow-up (non-finite or runaway speed, deep overlap, energy jump) raises
        before the contacts commit. Returns (fastest speed (m/s), deepest overlap (m))."""
        m = self.model
        dev = m.device
        n_contacts = cur.count
        self._scalar.zero_()
        self._launch("checks", broadphase.max_speed, dim=m.n_vertices, device=dev, inputs=[state_out.v, self._scalar])
        if n_contacts:
            self._launch("checks", narrowphase.contact_overlap, dim=n_contacts, device=dev, inputs=[
                n_contacts, cur.seg, m.arrays.seg_vertex, m.arrays.vertex_rod, m.arrays.radius,
                state_out.x, self._no_gaps, self._scalar[2:3]])
        sc = self._scalar.numpy()
        vmax_out = float(sc[0])
        depth = float(sc[2]) if n_contacts else 0.0
        if check:
            if sc[1] != 0.0:
                raise self._blowup(state_in, dt, theta, "non-finite velocity", control)
            limit = self.speed_limit_for(control)
            if vmax_out > limit:
                raise self._blowup(state_in, dt, theta, f"speed {vmax_out:.3g} m/s above the limit {limit:.3g} m/s",
                                   control)
            if depth > self.penetration_limit * m.min_diameter:
                raise self._blowup(state_in, dt, theta, f"rods overlap by {depth / m.min_diameter:.2f} d", control)
            if self.energy_check_every and state_out.step_index % self.energy_check_every == 0:
                self._check_energy(state_in, state_out, dt, theta, control)
        return vmax_out, depth


def run(solver: RodSolver, state: State, duration: float, dt: float, *, control=None, callback=None,
        every: int = 1, contacts: ContactPoints | None = None) -> State:
    """Step ``state`` forward by ``duration`` seconds with step ``dt``; returns the final state.

    Two states are ping-ponged; each step collides, then steps (``contacts``, when given, carry
    the warm start in and out). ``callback(state, info)`` is called every ``every`` steps with
    the state just written. The input ``state`` object is updated in place at the end.
    """
    n = _step_count(duration, dt)
    whole("every", every, ge=1)
    contacts = solver.contact_points() if contacts is None else contacts
    a = state
    b = State(solver.model)
    b.copy_from(a)
    for k in range(n):
        solver.collide(a, control, dt, contacts)
        info = solver.step(a, b, control, contacts, dt)
        a, b = b, a
        if callback is not None and (k + 1) % every == 0:
            callback(a, info)
    if a is not state:
        state.copy_from(a)
    return state


def _step_count(duration, dt) -> int:
    """Steps of ``dt`` s in ``duration`` s: ``duration`` >= 0, ``dt`` > 0, at most :data:`MAX_STEPS` steps."""
    T = real("duration", duration, ge=0, unit="s")
    h = real("dt", dt, gt=0, unit="s")
    steps = T / h  # inf when it overflows, refused below like any count too large
    if steps > MAX_STEPS:
        raise RodwarpError(f"duration {T:g} s at dt {h:g} s is {steps:.3g} steps, more than {MAX_STEPS:g}; "
                           f"raise dt or shorten duration")
    return int(round(steps))
