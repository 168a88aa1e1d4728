"""Walls of a scene, one tagged type: :class:`Plane`, :class:`Cylinder` and :class:`Cone`.

Each kind states its geometry once here, for the host (:meth:`distance`, used by checks and
tests) and as a row of the device's :class:`~rodwarp.kernels.structs.Walls` bundle
(:func:`device_rows`), whose device functions live in :mod:`rodwarp.kernels.walls`. A wall that
``moving`` follows the control's drive (a vibrated floor, a piston, a container lifted away:
:class:`~rodwarp.sim.control.Drive`). Walls are switched in and out by name in the
:class:`~rodwarp.sim.control.Control`; the model keeps them all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from rodwarp.errors import RodwarpError, RodwarpTypeError
from rodwarp.arguments import direction, real, vector
from rodwarp.sim._limits import MAX_LENGTH_M, friction

#: the device's kind codes (kernels/walls.py)
KINDS = {"plane": 0, "cylinder": 1, "cone": 2}


@dataclass
class _Wall:
    """What every wall kind holds besides its geometry: friction, whether it follows the
    control's drive, and its name (the kind's when not given). Keyword-only, so each kind's
    geometry comes first."""

    mu: float | None = field(default=0.2, kw_only=True)
    moving: bool = field(default=False, kw_only=True)
    name: str = field(default="", kw_only=True)
    kind = ""

    def __post_init__(self):
        if not self.name:
            self.name = self.kind


@dataclass
class Plane(_Wall):
    """Half-space wall {x : n . x >= offset} with Coulomb friction.

    Parameters
    ----------
    normal : (3,) array
        Unit normal pointing into the allowed region.
    offset : float
        Plane position n . x at rest (m).
    mu : float
        Friction coefficient against rods.
    moving : bool
        Whether the wall follows the drive of the control.
    name : str
        Label used by :meth:`Control.remove_walls` and in messages.
    """

    normal: np.ndarray
    offset: float
    kind = "plane"

    def distance(self, x, displacement=0.0, direction=(0.0, 0.0, 1.0)):
        """Signed distance (m) of points ``x`` (..., 3) from the surface, positive inside, with the
        drive displaced by ``displacement`` (m) along ``direction`` when the wall moves."""
        shift = float(np.dot(self.normal, direction)) * displacement if self.moving else 0.0
        return np.asarray(x, float) @ self.normal - (self.offset + shift)

    def device_row(self, drive_direction, moving: bool):
        """(geom0, geom1, shift) of the device bundle (kernels/walls.py, ``plane_surface``),
        the wall following the drive when ``moving``."""
        shift = float(self.normal @ drive_direction) if moving else 0.0
        return (*self.normal, self.offset), (0.0, 0.0, 0.0, 0.0), shift

    @classmethod
    def make(cls, normal, offset: float, *, mu: float | None = None, moving: bool = False, name: str = "plane"):
        """A plane with its normal normalised (any non-zero length); ``offset`` (m) within
        1e6 m; ``mu`` in [0, 10], None takes the model's."""
        n = direction("normal", normal)
        return cls(n, _length("offset", offset), mu=_mu(mu), moving=bool(moving), name=_name(name))


@dataclass
class Cylinder(_Wall):
    """The inside of a circular cylinder, {x : |(x - c) - a ((x - c) . a)| <= R}: rods are kept
    within ``radius`` of the axis through ``point`` along ``axis`` (infinitely long: close it
    with planes).

    Parameters
    ----------
    point : (3,) array
        A point of the axis at rest (m).
    axis : (3,) array
        Axis direction (normalised here).
    radius : float
        Radius of the inner surface (m).
    mu, moving, name
        As for :class:`Plane`; a moving cylinder's axis follows the drive.
    """

    point: np.ndarray
    axis: np.ndarray
    radius: float
    kind = "cylinder"

    def device_row(self, drive_direction, moving: bool):
        """(geom0, geom1, shift) of the device bundle (kernels/walls.py, ``cylinder_surface``; a
        moving cylinder's axis is displaced there)."""
        return (*self.point, self.radius), (*self.axis, 0.0), 0.0

    @classmethod
    def make(cls, point, axis, radius: float, *, mu: float | None = None, moving: bool = False,
             name: str = "cylinder"):
        """A cylinder with its axis normalised (any non-zero length); ``point`` (m) and
        ``radius`` (m, > 0) within 1e6 m; ``mu`` in [0, 10], None takes the model's."""
        p = vector("point", point, unit="m", limit=MAX_LENGTH_M)
        r = real("radius", radius, le=MAX_LENGTH_M, unit="m", hint="the cylinder's inner radius")
        if not r > 0:
            raise RodwarpError(f"radius must be a positive length (m), the cylinder's inner radius, got {r:g}")
        return cls(p, direction("axis", axis), r, mu=_mu(mu), moving=bool(moving), name=_name(name))

    def distance(self, x, displacement=0.0, direction=(0.0, 0.0, 1.0)):
        """As :meth:`Plane.distance`: R minus the distance from the axis (m)."""
        c = self.point + (np.asarray(direction, float) * displacement if self.moving else 0.0)
        rel = np.asarray(x, float) - c
        rho = rel - np.outer(rel @ self.axis, self.axis).reshape(rel.shape)
        return self.radius - np.linalg.norm(rho, axis=-1)


@dataclass
class Cone(_Wall):
    """The inside of a circular cone (a hopper, a funnel), {x : rho <= h tan(a)} with h = (x - p) . u
    the height along the axis above the apex p and rho the distance from the axis: rods are kept
    inside the cone opening from ``apex`` along ``axis`` (infinitely long: close it with planes).

    The distance to the surface is (h tan(a) - rho) cos(a) = h sin(a) - rho cos(a), positive
    inside. Its sign is right everywhere; its size is exact wherever the nearest surface point lies
    on a generator, which is every point inside and every point outside except those behind the
    apex (h cos(a) + rho sin(a) < 0, whose nearest surface point is the apex itself: there it
    understates the distance; a rod is never there unless it has left the cone).

    The distance is concave (linear in x minus cos(a) times the convex rho), so along a segment it
    is smallest at an endpoint: a capsule inside the cone touches it first with a vertex sphere,
    as for the cylinder. On the axis (rho = 0) a vertex sphere touches the cone along a circle and
    the normal is taken along the axis (the mean of that circle's normals).

    Parameters
    ----------
    apex : (3,) array
        The cone's apex at rest (m).
    axis : (3,) array
        The direction the cone opens toward (normalised here).
    half_angle : float
        Half the opening angle (rad), in (0, pi/2).
    mu, moving, name
        As for :class:`Plane`; a moving cone's apex follows the drive.
    """

    apex: np.ndarray
    axis: np.ndarray
    half_angle: float
    kind = "cone"

    def device_row(self, drive_direction, moving: bool):
        """(geom0, geom1, shift) of the device bundle (kernels/walls.py, ``cone_surface``; a moving
        cone's apex is displaced there): (apex, sin a), (unit axis, cos a)."""
        return (*self.apex, math.sin(self.half_angle)), (*self.axis, math.cos(self.half_angle)), 0.0

    @classmethod
    def make(cls, apex, axis, half_angle: float, *, mu: float | None = None, moving: bool = False,
             name: str = "cone"):
        """A cone with its axis normalised (any non-zero length); ``apex`` (m) within 1e6 m;
        ``half_angle`` (rad) in (0, pi/2); ``mu`` in [0, 10], None takes the model's."""
        p = vector("apex", apex, unit="m", limit=MAX_LENGTH_M)
        a = real("half_angle", half_angle, gt=0.0, lt=math.pi / 2, unit="rad", hint="half the cone's opening angle")
        return cls(p, direction("axis", axis), a, mu=_mu(mu), moving=bool(moving), name=_name(name))

    def distance(self, x, displacement=0.0, direction=(0.0, 0.0, 1.0)):
        """As :meth:`Plane.distance`: h sin(a) - rho cos(a) (m), exact except behind the apex."""
        c = self.apex + (np.asarray(direction, float) * displacement if self.moving else 0.0)
        rel = np.asarray(x, float) - c
        h = rel @ self.axis
        rho = rel - np.outer(h, self.axis).reshape(rel.shape)
        return h * math.sin(self.half_angle) - np.linalg.norm(rho, axis=-1) * math.cos(self.half_angle)


def _length(name: str, v) -> float:
    return real(name, v, ge=-MAX_LENGTH_M, le=MAX_LENGTH_M, unit="m")


def _mu(mu) -> float | None:
    return None if mu is None else friction("mu", mu)


def _name(name) -> str:
    if not isinstance(name, str):
        raise RodwarpTypeError(f"name must be a string (the wall's label), got {type(name).__name__} {name!r}")
    return name


def device_rows(walls, on, drive_direction, moving=None) -> dict:
    """Per-wall arrays of the device bundle (``kernels.structs.Walls``), one row per wall; a
    model without walls gets one inert row (arrays cannot be empty). ``on`` and ``moving``
    (default the walls' own flags) say per wall whether it is in place and follows the drive."""
    rows = max(len(walls), 1)
    out = {"kind": np.zeros(rows, dtype=np.int32), "geom0": np.zeros((rows, 4)), "geom1": np.zeros((rows, 4)),
           "moving": np.zeros(rows, dtype=np.int32), "shift": np.zeros(rows), "mu": np.zeros(rows),
           "on": np.zeros(rows, dtype=np.int32)}
    for k, w in enumerate(walls):
        mv = bool(w.moving if moving is None else moving[k])
        out["kind"][k] = KINDS[w.kind]
        out["geom0"][k], out["geom1"][k], out["shift"][k] = w.device_row(drive_direction, mv)
        out["mu"][k], out["on"][k], out["moving"][k] = w.mu, int(on[k]), int(mv)
    return out
