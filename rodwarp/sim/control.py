"""Time-varying inputs of a rod scene (:class:`Control`): walls in place, the drive, torques.

The model declares every wall a scene can have; a control says which are in place and how
the moving ones move, so a protocol that vibrates a closed container and then removes its
side walls changes only its control: the model and the states keep their sizes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import warp as wp

from rodwarp.errors import RodwarpError, RodwarpTypeError
from rodwarp.arguments import direction as _direction
from rodwarp.arguments import real
from rodwarp.sim._limits import MAX_FREQUENCY, MAX_LENGTH_M, MAX_SPEED


@dataclass
class Drive:
    """Prescribed displacement of the moving walls along ``direction`` (m): A sin(2 pi f (t -
    phase_time)) (a vibrated floor), or a ramp (``ramp`` True): from ``ramp_start`` at
    ``ramp_speed`` from ``phase_time`` for ``ramp_duration``, then held (a piston that
    compresses, a container lifted away)."""

    amplitude: float = 0.0
    frequency: float = 0.0
    direction: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    phase_time: float = 0.0
    ramp_speed: float = 0.0
    ramp_duration: float = math.inf
    ramp_start: float = 0.0
    ramp: bool = False
    from_rest: bool = False

    def displacement(self, t: float) -> float:
        """Displacement at time t (m)."""
        if self.ramp:
            return self.ramp_start + self.ramp_speed * min(max(t - self.phase_time, 0.0), self.ramp_duration)
        if self.amplitude == 0.0 or self.frequency == 0.0:
            return 0.0
        if self.from_rest:  # starts at rest at its lowest point: no jump in position or velocity
            return self.amplitude * (1.0 - math.cos(2.0 * math.pi * self.frequency * (t - self.phase_time)))
        return self.amplitude * math.sin(2.0 * math.pi * self.frequency * (t - self.phase_time))

    @property
    def peak_speed(self) -> float:
        """Fastest wall speed (m/s): 2 pi f |A|, or the ramp's speed."""
        if self.ramp:
            return abs(self.ramp_speed)
        return 2.0 * math.pi * self.frequency * abs(self.amplitude)


class Control:
    """Which walls of ``model`` are in place, the drive of the moving ones, applied axial torques.

    Parameters
    ----------
    model : Model
        The scene whose walls (``model.walls``) this control switches.
    """

    def __init__(self, model):
        self.model = model
        self.on = np.ones(len(model.walls), dtype=bool)
        self.moving = np.array([w.moving for w in model.walls], dtype=bool)
        self.drive = Drive()
        self._torque = None

    # ------------------------------------------------------------------ walls
    def _sync(self) -> None:
        # walls added to the model after this control was made are in place
        n = len(self.model.walls)
        if self.on.size < n:
            self.on = np.concatenate([self.on, np.ones(n - self.on.size, dtype=bool)])
            self.moving = np.concatenate([self.moving, [w.moving for w in self.model.walls[self.moving.size:]]])

    def _names(self, names) -> set:
        names = {names} if isinstance(names, str) else set(names)
        known = {p.name for p in self.model.walls}
        unknown = sorted(names - known)
        if unknown:
            raise RodwarpError(f"no wall named {', '.join(unknown)}; the model has {', '.join(sorted(known))}")
        return names

    def remove_walls(self, names) -> None:
        """Take walls out by name (e.g. the side walls and lid before the stability test)."""
        self._sync()
        names = self._names(names)
        for k, p in enumerate(self.model.walls):
            if p.name in names:
                self.on[k] = False

    def restore_walls(self, names=None) -> None:
        """Put walls back in place (all when ``names`` is None)."""
        self._sync()
        for k, p in enumerate(self.model.walls):
            if names is None or p.name in set(names):
                self.on[k] = True

    def set_moving(self, names) -> None:
        """Exactly the walls ``names`` follow the drive (the model's ``moving`` flags say which
        do by default): a scene whose floor is shaken in one stage and whose piston presses in
        another."""
        self._sync()
        names = self._names(names)
        self.moving = np.array([p.name in names for p in self.model.walls], dtype=bool)

    def walls_in_place(self) -> list[str]:
        self._sync()
        return [p.name for k, p in enumerate(self.model.walls) if self.on[k]]

    def set_drive(self, amplitude: float, frequency: float, direction=(0.0, 0.0, 1.0), phase_time: float = 0.0,
                  from_rest: bool = False) -> None:
        """Moving walls follow x = A sin(2 pi f (t - phase_time)) along ``direction`` (m, Hz); with
        ``from_rest``, x = A (1 - cos(2 pi f (t - phase_time))): the same oscillation started at
        rest at its lowest point, so a pile resting on the wall is not struck at the drive's
        peak speed in the first step. ``amplitude`` within 1e6 m, ``frequency`` in [0, 1e6] Hz,
        ``phase_time`` (s) finite, ``direction`` any non-zero vector."""
        a = real("amplitude", amplitude, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, unit="m")
        f = real("frequency", frequency, ge=0, le=MAX_FREQUENCY, unit="Hz")
        self.drive = Drive(a, f, _direction("direction", direction), real("phase_time", phase_time, unit="s"),
                           from_rest=bool(from_rest))

    def set_ramp(self, speed: float, duration: float = math.inf, direction=(0.0, 0.0, 1.0),
                 start_time: float = 0.0, start: float = 0.0) -> None:
        """Moving walls travel at ``speed`` (m/s) along ``direction`` from ``start_time`` (s) for
        ``duration`` (s), then stay: a piston pressing by speed x duration, a container lifted
        away. ``start`` (m) is their displacement when the ramp begins (a piston already
        lowered onto the packing). ``speed`` within 1e3 m/s, ``start`` within 1e6 m,
        ``duration`` > 0 s (``math.inf``: for ever), ``start_time`` (s) finite."""
        v = real("speed", speed, ge=-MAX_SPEED, le=MAX_SPEED, unit="m/s")
        s0 = real("start", start, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, unit="m")
        # inf is the documented "never stops"; every other duration must be a positive number
        T = math.inf if duration == math.inf else real("duration", duration, gt=0, unit="s")
        t0 = real("start_time", start_time, unit="s")
        self.drive = Drive(direction=_direction("direction", direction), phase_time=t0, ramp_speed=v,
                           ramp_duration=T, ramp_start=s0, ramp=True)

    def floor_height(self, t: float) -> float | None:
        """Height z (m) at time t of the wall named ``floor`` (moving with the drive when it is
        ``moving``); None when the scene has no floor in place."""
        self._sync()
        for k, p in enumerate(self.model.walls):
            if p.name == "floor" and p.kind == "plane" and self.on[k]:
                z = p.offset / p.normal[2] if abs(p.normal[2]) > 0 else p.offset
                if self.moving[k]:
                    z += float(self.drive.direction[2]) * self.drive.displacement(t)
                return float(z)
        return None

    # ------------------------------------------------------------------ torques
    def set_torque(self, torque) -> None:
        """Axial torque on the edges (N m): one value per rod (spread over its edges by their
        share of the rod's axial inertia) or one per vertex slot (V,); None removes it."""
        m = self.model
        if torque is None:
            self._torque = None
            return
        t = _torques(torque)
        if t.size == m.n_rods:
            I = m.inertia_np
            tot = np.bincount(m.vertex_rod_np, weights=I, minlength=m.n_rods)
            t = t[m.vertex_rod_np] * I / np.where(tot > 0, tot, 1.0)[m.vertex_rod_np]
        if t.size != m.n_vertices:
            raise RodwarpError(f"torque needs {m.n_rods} (per rod) or {m.n_vertices} (per vertex slot) values, "
                               f"got {t.size}")
        self._torque = wp.array(t, dtype=wp.float64, device=m.device)

    def torque(self):
        """Axial torques per edge slot on the device (zeros when none are applied)."""
        if self._torque is None:
            self._torque = wp.zeros(self.model.n_vertices, dtype=wp.float64, device=self.model.device)
        return self._torque


def _torques(torque) -> np.ndarray:
    """``torque`` as a flat float64 array of finite values (N m)."""
    try:
        t = np.asarray(torque, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise RodwarpTypeError(f"torque must be numbers (N m), one per rod or per vertex slot, got "
                        f"{type(torque).__name__}") from None
    if isinstance(torque, (str, bytes)):
        raise RodwarpTypeError(f"torque must be numbers (N m), one per rod or per vertex slot, got {torque!r}")
    if not np.all(np.isfinite(t)):
        raise RodwarpError(f"torque must be finite (N m), got {t[~np.isfinite(t)][0]} at index "
                           f"{int(np.flatnonzero(~np.isfinite(t))[0])}")
    return t
