"""Step bounds of a scene and the step the solver takes: the time-step side of :class:`RodSolver`.

The *step bound* is the largest time step a scene resolves (docs/physics.md, "Step bounds and
the adaptive step"): the smaller of

* the contact resolution bound: a rod crosses at most ``reach`` diameters per step relative
  to the walls, d_min / (v + v_drive), so speculative contacts see every approach; and
  gravity alone moves a resting vertex by at most 1% of a diameter per step,
  g dt^2 <= 0.01 d_min, which keeps frictional stacks from creeping;
* with explicit (symplectic) bending, its numerical stability bound 2 / omega_max.

It is not the *stability test* of the protocol (the vibrated pile, :mod:`rodwarp.experiments`):
the methods keep their historical names (``max_stable_dt`` is the step bound, and
:meth:`StepBounds.step_bound` its new name). The default step is a fraction of the bound and at
least 40 steps per drive period; the adaptive step recomputes it at the fastest vertex speed
every step. Rodwarp's constraints need none of the explicit axial limit h / sqrt(E / rho).
"""

from __future__ import annotations

import math
import warnings

import numpy as np

from rodwarp.errors import RodwarpError, StepTooLarge

#: the fewest steps per period of a drive: the default step never exceeds 1 / (40 f), which the
#: protocol's checks count on (rodwarp.experiments._plan)
STEPS_PER_PERIOD = 40.0


class StepBounds:
    """The step bounds, default and adaptive steps and the step guard of :class:`RodSolver`.

    A mixin: the solver provides ``model``, ``bending``, ``guard_factor``, ``allow_unstable``,
    ``steps_per_period``, ``_eb_dt`` (the cached explicit-bending bound), ``_char_speed`` (a dict: the cached
    characteristic speed per drive) and ``_control(control)``.
    """

    def explicit_bending_dt(self) -> float:
        """Numerical stability bound of symplectic (explicit) bending, 2 / omega_max (s; cached)."""
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

    def characteristic_speed(self, control=None) -> float:
        """Free-fall speed over the scene height plus the drive's peak speed (m/s)."""
        m = self.model
        control = self._control(control)
        # a property of the model and the drive alone, read every step: computed once per drive
        key = (control.drive.peak_speed, None if m.box is None else m.box.tobytes(), tuple(m.gravity))
        if key not in self._char_speed:
            self._char_speed[key] = self._characteristic_speed(control)
        return self._char_speed[key]

    def _characteristic_speed(self, control) -> float:
        m = self.model
        bb = m.box if m.box is not None else m.rods.bounding_box()
        g = float(np.linalg.norm(m.gravity))
        # the fall height is the scene's extent along gravity, not its widest side
        down = m.gravity / g if g > 0 else np.array([0.0, 0.0, -1.0])
        height = float(np.abs(bb[1] - bb[0]) @ np.abs(down))
        v0 = 0.0 if m.rods.velocities is None else float(np.linalg.norm(m.rods.velocities, axis=1).max())
        return math.sqrt(2.0 * g * height) + control.drive.peak_speed + v0 + 1e-3

    def contact_dt(self, control=None, speed: float | None = None, reach: float = 1.0) -> float:
        """Resolution bound of the contact model (s): a rod crosses at most one diameter per
        step relative to the walls, so speculative contacts see every approach and the
        linearised normals stay valid; and gravity alone moves a resting vertex by at most 1%
        of a diameter per step (g dt^2 <= 0.01 d), which keeps frictional stacks from creeping.

        ``speed`` (m/s) is the fastest vertex now; without it, the worst case of the scene
        (free fall over its height, :meth:`characteristic_speed`), which holds whatever happens.
        """
        control = self._control(control)
        d = self.model.min_diameter
        if speed is None:
            v = self.characteristic_speed(control)
        else:
            v = float(speed) + control.drive.peak_speed + 1e-3
        b = reach * d / v
        g = float(np.linalg.norm(self.model.gravity))
        if g > 0:
            b = min(b, math.sqrt(0.01 * d / g))
        return b

    def step_bound(self, bending: str | None = None, control=None, speed: float | None = None,
                   reach: float = 1.0) -> float:
        """Step bound of this scene for the chosen bending integration (s): the contact
        resolution bound (:meth:`contact_dt`) at ``speed`` (m/s) when given, else for the
        worst case, and with explicit bending its stability bound too. ``reach``: diameters a
        rod may cross per step."""
        mode = bending or self.bending
        b = self.contact_dt(control, speed, reach)
        if mode == "explicit":
            b = min(b, self.explicit_bending_dt())
        return b

    def max_stable_dt(self, bending: str | None = None, control=None, speed: float | None = None,
                      reach: float = 1.0) -> float:
        """The step bound (s): an alias of :meth:`step_bound`."""
        return self.step_bound(bending, control, speed, reach)

    def default_dt(self, control=None, safety: float = 0.5, speed: float | None = None,
                   shrink: float = 1.0) -> float:
        """Default step: ``safety`` x the step bound, times ``shrink``, and at least
        ``steps_per_period`` steps per drive period (the solver's; 40 unless set).

        Above 1 the safety lets the fastest rod cross more diameters per step (speculative
        contacts still see every approach) but leaves the other bounds as they are: gravity's
        g dt^2 <= 0.01 d (a resting rod on a floor at twice that step, g dt^2 = 0.04 d, kept a
        velocity of 1.4 um/s forever) and explicit bending's stability. ``shrink`` (the
        adaptive step's overlap feedback) scales the whole step."""
        control = self._control(control)
        dt = shrink * min(safety, 1.0) * self.step_bound(control=control, speed=speed, reach=max(safety, 1.0))
        f = control.drive.frequency
        if f > 0:
            dt = min(dt, 1.0 / (self.steps_per_period * f))
        return dt

    #: overlap (in diameters of the thinnest rod) above which the adaptive step shrinks: a
    #: larger target lets an elastic pile sink measurably into itself, a smaller one costs
    #: time (docs/physics.md, "Step bounds and the adaptive step"); a shaken rigid pile rarely
    #: reaches it
    OVERLAP_TARGET = 0.02

    def adaptive_dt(self, control, speed: float, previous: float | None = None, safety: float = 1.0,
                    growth: float = 1.25, overlap: float | None = None) -> float:
        """A step that follows the motion (s): :meth:`default_dt` at the current fastest
        vertex speed, growing by at most ``growth`` per step (falling at once), so a resting
        pile takes large steps and an impact small ones. Deterministic: the same state and
        previous step give the same step.

        Parameters
        ----------
        speed : float
            Fastest vertex speed at the end of the last step (m/s), ``StepInfo.max_speed``.
        previous : float, optional
            The last step (s).
        safety : float
            Diameters the fastest rod may cross per step.
        overlap : float, optional
            Deepest rod-rod overlap after the last step (m), ``StepInfo.max_overlap``. Above
            :attr:`OVERLAP_TARGET` diameters the safety shrinks in proportion (to at most a
            quarter), since the overlap a step leaves grows with the step.
        """
        shrink = 1.0
        if overlap is not None and overlap > 0:
            target = self.OVERLAP_TARGET * self.model.min_diameter
            if overlap > target:
                shrink = max(0.25, target / overlap)
        dt = self.default_dt(control, safety=safety, speed=speed, shrink=shrink)
        if previous is not None and previous > 0:
            dt = min(dt, growth * previous)
        return dt

    def adaptive_step(self, state_in, state_out, control, contacts, dt: float, min_fraction: float = 1.0 / 64):
        """:meth:`collide` and :meth:`step` by ``dt``, retried at half the guard's bound while the
        guard refuses it (``contacts`` as for :meth:`step`; None: the solver's own).

        The adaptive step sizes a step from the speeds the last one ended with; the guard
        checks the speeds after this step's predictor (gravity, explicit bending, torques),
        which an impact or a bending wave can raise. A refused step leaves ``state_in``
        untouched (and the contacts' last impulses), so the retry starts from the same state:
        deterministic, and resume stays bit for bit.

        Returns
        -------
        (StepInfo, float, int)
            The step's diagnostics, the step taken (s) and the number of refused tries.
        """
        refused = 0
        first = dt
        while True:
            try:
                if contacts is None:
                    return self.step(state_in, state_out, control, None, dt), dt, refused
                self.collide(state_in, control, dt, contacts)
                return self.step(state_in, state_out, control, contacts, dt), dt, refused
            except StepTooLarge as e:
                refused += 1
                dt = 0.5 * min(dt, e.bound)
                if dt < min_fraction * first:
                    raise

    def theta_for(self, dt: float, touching: bool = False) -> float:
        """Bending integration of a step of ``dt`` s: 0 explicit (symplectic), 1 implicit Euler.

        ``auto`` bends rods implicitly whenever they can touch something (``touching``: rod
        contacts at the start of the step, or a wall in place), and explicitly only in a
        contact-free scene below 0.8 of the explicit bound. Symplectic Euler conserves a
        modified energy with a cross term in position and velocity, and the inelastic velocity
        projection of a contact can raise it: in a dense shaken pile of alpha-200 rods at
        g = 0.5 this pumped the pile's kinetic and bending energy from 170 J to 450 J within
        0.03 s of the drive stopping, at 0.36 of the explicit bound; implicit bending from the
        same state let it decay to 4 J (docs/physics.md, "Bending integration").
        """
        if self.bending == "implicit" or self.model.curved:
            return 1.0
        if self.bending == "explicit":
            return 0.0
        if touching:
            return 1.0
        return 0.0 if dt <= 0.8 * self.explicit_bending_dt() else 1.0

    def check_dt(self, dt: float, control=None, speed: float | None = None) -> None:
        """Refuse (or, with ``allow_unstable``, flag) a step above the step bound (at
        ``speed`` when given, see :meth:`contact_dt`)."""
        if not (dt > 0 and math.isfinite(dt)):
            raise RodwarpError(f"time step must be a positive number, got {dt}")
        control = self._control(control)
        if speed is not None and not self._can_touch(control):
            # nothing to touch: the contact bound does not apply, only explicit bending's
            if self.bending != "explicit" or dt <= self.explicit_bending_dt():
                return
        # at the actual speeds, speculative contacts resolve approaches of up to two diameters
        # per step (the narrowphase's reach covers twice the travel)
        bound = self.step_bound(control=control, speed=speed, reach=self.guard_factor if speed is not None else 1.0)
        if dt > bound * (1.0 + 1e-9):
            msg = (f"time step {dt:.3g} s exceeds this scene's step bound {bound:.3g} s (its numerical stability "
                   f"bound: {self._bound_reason(control, speed)}); use dt <= {bound:.3g} s")
            if not self.allow_unstable:
                raise StepTooLarge(msg + " or allow_unstable=True", bound)
            warnings.warn(msg, stacklevel=3)

    def _can_touch(self, control) -> bool:
        """Whether any contact is possible: rod-rod contacts on, or a wall in place."""
        m = self.model
        return (m.rod_contacts and m.n_segments > 1) or bool(len(m.walls) and control.walls_in_place())

    def _bound_reason(self, control=None, speed=None) -> str:
        if self.bending == "explicit" and self.explicit_bending_dt() < self.contact_dt(control, speed):
            return "explicit bending, 2/omega_max"
        if speed is None:
            return "contact resolution, d_min / characteristic speed"
        return f"contact resolution, d_min / (fastest vertex {speed:.3g} m/s + drive speed)"
