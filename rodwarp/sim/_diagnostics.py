"""The solver's checks and diagnostics (a mixin of :class:`~rodwarp.sim.solver.RodSolver`): the
energy-jump and speed guards that turn a runaway step into :class:`SimulationBlowUp` with its
likely cause, the full contact residual of the last step, and the energies of a state.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import warp as wp

from rodwarp.errors import RodwarpError, SimulationBlowUp
from rodwarp.kernels import elastics, frames, friction, wall_contacts

if TYPE_CHECKING:
    from rodwarp.sim.state import State


class SolverChecks:
    """Checks of :class:`~rodwarp.sim.solver.RodSolver` (its attributes: ``model``, ``factors``,
    ``iterations``, the last solve and the launch helper)."""

    def _check_energy(self, state_in: State, state_out: State, dt: float, theta: float, control) -> None:
        """Energy-jump test: kinetic + elastic energy may not grow 4x between checks beyond
        what the scene can supply (all mass at the characteristic speed)."""
        e = self.energy(state_out)
        mech = e["kinetic"] + e["bending"] + e["stretching"] + e["twist"]
        floor = 0.5 * self.model.total_mass() * self.characteristic_speed(control) ** 2
        # the last check of the same trajectory only: a solver stepping another state (a
        # restarted run, a benchmark's repeat) starts its comparison afresh
        prev = self._last_mech
        if getattr(self, "_last_mech_step", None) != state_out.step_index - self.energy_check_every:
            prev = None
        self._last_mech = mech
        self._last_mech_step = state_out.step_index
        if not math.isfinite(mech):
            raise self._blowup(state_in, dt, theta, "non-finite energy", control)
        if prev is not None and mech > 4.0 * prev + floor:
            raise self._blowup(state_in, dt, theta,
                               f"energy jump from {prev:.3g} J to {mech:.3g} J within {self.energy_check_every} steps",
                               control)

    @property
    def speed_limit(self) -> float:
        return self.speed_limit_for(None)

    def speed_limit_for(self, control) -> float:
        if self._speed_limit is not None:
            return self._speed_limit
        return 20.0 * (self.characteristic_speed(control) + (self._v_elastic or 0.0))

    def _blowup(self, state_in: State, dt: float, theta: float, what: str, control=None) -> SimulationBlowUp:
        step = state_in.step_index + 1
        t = state_in.time + dt
        eb = self.explicit_bending_dt()
        if theta == 0.0 and dt > eb:
            cause = f"explicit bending at dt = {dt:.3g} s above its bound {eb:.3g} s; use bending='implicit' or a smaller step"
        elif "overlap" in what:
            cause = (f"contacts under-resolved (tunnelling or too few iterations: {self.iterations}); "
                     f"lower dt (now {dt:.3g} s, contact bound {self.contact_dt(control):.3g} s) or raise iterations")
        else:
            cause = (f"step {dt:.3g} s too large for this scene (step bound {self.step_bound(control=control):.3g} s) "
                     f"or too few iterations")
        return SimulationBlowUp(f"simulation blew up at step {step} (t = {t:.6g} s): {what}; likely cause: {cause}",
                                step=step, time=t, cause=cause)

    # ------------------------------------------------------------------ diagnostics
    def full_residual(self, state_out: State) -> float:
        """Largest velocity change (m/s) one more exact local solve of any contact, rod-rod or
        wall, would make after the last :meth:`step` (which wrote ``state_out``): the
        residual of every contact (the step itself reports only its last sweep's largest change)."""
        if self._last_solve is None:
            raise RodwarpError("full_residual measures the last step: call step() first")
        contacts, params, walls, wc = self._last_solve
        m = self.model
        out = wp.zeros(1, dtype=wp.float64, device=m.device)
        # the contacts read rigid rods as bodies, as inside the sweeps
        v, spin = wp.clone(state_out.v), wp.clone(state_out.spin)
        wp.launch(friction.rigid_bodies_to_sweeps, dim=m.n_rods, device=m.device, inputs=[
            m.arrays, self.factors.tangent, v, spin, wp.zeros_like(self.factors.axial)])
        if contacts.count:
            wp.launch(friction.rod_contact_residual, dim=contacts.count, device=m.device, inputs=[
                contacts, self._frames, params, v, spin, out])
        n = int(self._n_wall_frames.numpy()[0])
        if n:
            wp.launch(wall_contacts.wall_contact_residual, dim=n, device=m.device, inputs=[
                walls, params, wc, v, spin, out])
        return float(out.numpy()[0])

    def energy(self, state: State) -> dict:
        """Kinetic (translation and spin), potential (gravity), bending, stretching and twist
        energy (J) of ``state``."""
        m = self.model
        rs = state.rod_state()
        self._launch("checks", frames.step_frames, dim=m.n_rods, device=m.device, inputs=[m.arrays, rs, self.factors])
        self._energy_out.zero_()
        self._launch("checks", elastics.elastic_energy, dim=m.n_rods, device=m.device, inputs=[
            m.arrays, rs, self.factors.bend_target, self.factors.ref_twist, wp.vec3d(*m.gravity), self._energy_out])
        k, p, b, s, tw = (float(x) for x in self._energy_out.numpy())
        return {"kinetic": k, "potential": p, "bending": b, "stretching": s, "twist": tw,
                "total": k + p + b + s + tw}
