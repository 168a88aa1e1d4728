"""The launches of a step's solve (:class:`SolveLaunches`, a part of
:class:`~rodwarp.sim.solver.RodSolver`): the walls bundle of a step, the wall contacts' view,
Gauss-Seidel sweeps as separate launches over coloured contacts (the GPU path) and the
post-stabilisation of positions. The sequential (CPU) device runs the same loops fused in one
launch each (``kernels/solve.py``, ``kernels/overlap.py``)."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from rodwarp.kernels import elastics, friction, overlap, wall_contacts
from rodwarp.kernels.structs import WallContacts, Walls
from rodwarp.sim.state import cached_view
from rodwarp.sim.walls import device_rows


class SolveLaunches:
    """Solve launches of :class:`~rodwarp.sim.solver.RodSolver` (its attributes: ``model``,
    ``factors``, ``collision``, ``iterations``, ``tolerance``, the scratch buffers and ``_launch``)."""

    def _walls(self, control, t: float, dt: float) -> Walls:
        """The Walls bundle of this step: per-wall arrays copied only when the control's walls
        change; the drive enters as three scalars."""
        m = self.model
        P = len(m.walls)
        key = (id(control), P, tuple(control.on.tolist()), tuple(control.moving.tolist()),
               tuple(control.drive.direction.tolist()))
        w = self._walls_struct
        if w is None or self._walls_key != key:
            dev = m.device
            rows = device_rows(m.walls, control.on, control.drive.direction, control.moving)
            w = self._walls_struct = Walls()
            w.n = P
            for name, a in rows.items():
                dtype = wp.vec4d if a.ndim == 2 else (wp.int32 if a.dtype == np.int32 else wp.float64)
                setattr(w, name, wp.array(a, dtype=dtype, device=dev))
            w.drive_dir = wp.vec3d(*control.drive.direction)
            self._walls_key = key
        d0 = control.drive.displacement(t)
        d1 = control.drive.displacement(t + dt)
        w.drive_disp = wp.float64(d0)
        w.drive_vel = wp.float64((d1 - d0) / dt)
        return w

    def _wall_contacts(self, cur) -> WallContacts:
        # one view per contact buffer (the solved one alternates), kept on the buffer itself
        return cached_view(cur.__dict__, "_wall_contacts", WallContacts, gap=self._wall_gap,
                           normal=self._wall_normal,
                           impulse=cur.wall_impulse, active=self._active, n_active=self._n_active,
                           span=self._wall_span, key=self._wall_key, frames=self._wall_frames,
                           n_frames=self._n_wall_frames)

    def _project_positions(self, rs_in, state_out, contacts, walls, wc, params, P):
        """Post-stabilisation: overlaps beyond the slop removed from the end-of-step positions
        (velocities untouched), so the velocity solve carries no Baumgarte term. Returns the
        sweeps run."""
        m = self.model
        dev = m.device
        f = self.factors
        if self.fused:
            self._launch("friction", overlap.project_positions_sequential, dim=1, device=dev, inputs=[
                self.position_sweeps, wp.float64(self.position_tolerance * m.min_diameter), m.arrays, rs_in.x,
                contacts, self._frames, f.tangent, walls, wc, params, state_out.x, self._proj_out])
            return int(self._proj_out.numpy()[1])
        n_active = int(self._n_active.numpy()[0]) if P else 0
        for _ in range(self.position_sweeps):
            if contacts.count:
                ids = self.collision.color_ids
                if self.coloring:
                    for c0, c1 in self.collision.color_ranges:
                        self._launch("friction", overlap.project_rod_contacts, dim=c1 - c0, device=dev,
                                     inputs=[ids[c0:c1], 1, m.arrays, contacts, self._frames, params, rs_in.x,
                                             f.tangent, state_out.x])
                else:
                    self._launch("friction", overlap.project_rod_contacts, dim=contacts.count, device=dev,
                                 inputs=[ids, 0, m.arrays, contacts, self._frames, params, rs_in.x, f.tangent,
                                         state_out.x])
            if n_active:
                self._launch("friction", overlap.project_wall_contacts, dim=n_active, device=dev, inputs=[
                    m.arrays, rs_in.x, f.tangent, walls, wc, params, state_out.x])
        return self.position_sweeps

    def _sweeps(self, rs_in, state_out, contacts, walls, wc, params, P):
        """Gauss-Seidel sweeps as separate launches (coloured contacts; the GPU path)."""
        m = self.model
        dev = m.device
        f = self.factors
        n_active = int(self._n_active.numpy()[0]) if P else 0
        n_contacts = contacts.count
        ids = self.collision.color_ids
        used = 0
        self._launch("friction", friction.rigid_bodies_to_sweeps, dim=m.n_rods, device=dev, inputs=[
            m.arrays, f.tangent, state_out.v, state_out.spin, f.axial])
        for it in range(self.iterations):
            measure = it == self.iterations - 1 or (self.tolerance > 0 and it % 2 == 1)
            if measure:
                self._residual.zero_()
                self._sresidual.zero_()
            if n_contacts:
                args = [m.arrays, contacts, self._frames, params, state_out.v, state_out.spin, self._residual]
                if self.coloring:
                    for c0, c1 in self.collision.color_ranges:
                        self._launch("friction", friction.solve_rod_contacts, dim=c1 - c0, device=dev,
                                     inputs=[ids[c0:c1], 1, *args])
                else:
                    self._launch("friction", friction.solve_rod_contacts, dim=n_contacts, device=dev,
                                 inputs=[ids, 0, *args])
            if n_active:
                self._launch("friction", wall_contacts.solve_wall_contacts, dim=n_active, device=dev, inputs=[
                    walls, params, wc, state_out.v, state_out.spin, self._residual])
            self._launch("elastics", elastics.rod_projection, dim=m.n_rods, device=dev, inputs=[
                m.arrays, rs_in, state_out.v, state_out.spin, f, params.dt, self._sresidual])
            used = it + 1
            if measure and self.tolerance > 0 and it < self.iterations - 1:
                if (self._residual.numpy()[0] < self.tolerance ** 2
                        and self._sresidual.numpy()[0] < self.length_tolerance):
                    break
        self._launch("friction", friction.rigid_bodies_from_sweeps, dim=m.n_rods, device=dev, inputs=[
            m.arrays, f.tangent, state_out.v, state_out.spin, f.axial])
        self._launch("elastics", elastics.rigid_length_projection, dim=m.n_rods, device=dev, inputs=[
            m.arrays, rs_in, state_out.v, f, params.dt, wp.float64(self.length_tolerance), self._sresidual])
        # the contact residual is kept squared on the device
        return math.sqrt(float(self._residual.numpy()[0])), float(self._sresidual.numpy()[0]), used
