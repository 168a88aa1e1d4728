"""The rod set: one host-side (NumPy) container for simulation, segmentation and analysis.

A :class:`RodSet` holds N polyline rods with all vertices concatenated in one ``(V, 3)``
array and a CSR-style ``offsets`` array, so rod ``r`` owns ``points[offsets[r]:offsets[r+1]]``.
Coordinates, radii, gaps and the box are in ``units`` (``"m"``, ``"mm"``, ``"um"`` or
``"voxel"``); velocities are in ``units`` per second.

Files: ``.npz`` and ``.zarr`` keep everything (see ``docs/rodset-format.md``); ``.csv`` keeps
only ``rod,x,y,z,radius``. Every write is atomic. All bad input raises
:class:`~rodwarp.errors.RodwarpError` with a one-line message.

This module must not import warp.
"""

from __future__ import annotations

import copy as _copy
import csv
import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from rodwarp.atomic import _json_default, atomic_path
from rodwarp.errors import RodwarpError

__all__ = ["UNITS", "FORMAT_NAME", "FORMAT_VERSION", "Contacts", "RodSet", "load"]

#: Metres per unit. ``voxel`` has no fixed metric scale (pass ``voxel_size`` to convert).
UNITS: dict[str, float | None] = {"m": 1.0, "mm": 1e-3, "um": 1e-6, "voxel": None}
#: Decimal exponent of each metric unit, used for exact powers-of-ten conversion.
_EXPONENT = {"m": 0, "mm": -3, "um": -6}

FORMAT_NAME = "rodwarp.rodset"
FORMAT_VERSION = 1
SUPPORTED_SUFFIXES = (".npz", ".zarr", ".csv")

_CONTACT_KEYS = ("contact_rod_i", "contact_rod_j", "contact_point", "contact_gap")
_OPTIONAL_KEYS = ("rest_points", "velocities", "box")


# ----------------------------------------------------------------------------------------------
# small helpers
# ----------------------------------------------------------------------------------------------

def _fail(msg: str) -> RodwarpError:
    """Build a RodwarpError whose message is guaranteed to be one line."""
    return RodwarpError(" ".join(str(msg).split()))


def _float_array(a, name: str) -> np.ndarray:
    try:
        return np.asarray(a, dtype=np.float64, order="C")
    except (TypeError, ValueError) as e:
        raise _fail(f"{name} must be numeric: {e}") from None


def _int_array(a, name: str) -> np.ndarray:
    try:
        arr = np.asarray(a)
    except (TypeError, ValueError) as e:
        raise _fail(f"{name} must be an integer array: {e}") from None
    if arr.dtype.kind in "iu":
        return np.asarray(arr, dtype=np.int64, order="C")
    if arr.dtype.kind != "f" and arr.size:
        raise _fail(f"{name} must hold integers, got dtype {arr.dtype}")
    f = np.asarray(arr, dtype=np.float64)
    if f.size and (not np.all(np.isfinite(f)) or np.any(f != np.round(f))):
        raise _fail(f"{name} must hold whole numbers; got non-integer values")
    return np.asarray(f, dtype=np.int64, order="C")


def _check_finite(a: np.ndarray, name: str) -> None:
    if a.size and not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        where = f"row {bad[0]}" if a.ndim > 1 else f"index {bad[0]}"
        raise _fail(f"{name} contains NaN or inf (first at {where}); remove or fix those values")


def _check_units(units) -> str:
    if not isinstance(units, str) or units not in UNITS:
        raise _fail(f"unknown units {units!r}; use one of {', '.join(repr(u) for u in UNITS)}")
    return units


def _unit_scale(src: str, dst: str, voxel_size: float | None) -> tuple[float, bool]:
    """Return ``(k, divide)``: converting ``src`` values to ``dst`` is ``x / k`` if divide else ``x * k``.

    Metric conversions use exact powers of ten, multiplying for factors >= 1 and dividing
    otherwise, so each value is correctly rounded (``m -> mm`` is exactly ``x * 1000``).
    """
    _check_units(src)
    _check_units(dst)
    if voxel_size is not None:
        if "voxel" not in (src, dst) or src == dst:
            raise _fail(f"voxel_size only applies to conversions to or from 'voxel' (got {src!r} -> {dst!r})")
        try:
            voxel_size = float(voxel_size)
        except (TypeError, ValueError):
            raise _fail(f"voxel_size must be a positive number in metres, got {voxel_size!r}") from None
        if not (math.isfinite(voxel_size) and voxel_size > 0):
            raise _fail(f"voxel_size must be a positive number in metres, got {voxel_size!r}")
    if src == dst:
        return 1.0, False
    if "voxel" in (src, dst):
        if voxel_size is None:
            raise _fail(f"cannot convert {src!r} to {dst!r} without a scale; pass voxel_size= (metres per voxel)")
        # metric units are m, mm, um (exponent <= 0), so one voxel is voxel_size * 10**-e of them
        if src == "voxel":
            return voxel_size * 10.0 ** (-_EXPONENT[dst]), False
        return voxel_size * 10.0 ** (-_EXPONENT[src]), True
    k = _EXPONENT[src] - _EXPONENT[dst]
    return (10.0 ** k, False) if k >= 0 else (10.0 ** (-k), True)


def _scale(a: np.ndarray | None, k: float, divide: bool) -> np.ndarray | None:
    if a is None:
        return None
    return a / k if divide else a * k


# ----------------------------------------------------------------------------------------------
# Contacts
# ----------------------------------------------------------------------------------------------

@dataclass(eq=False)
class Contacts:
    """Rod-rod contacts of one configuration.

    Attributes
    ----------
    rod_i, rod_j : (K,) int64
        Rod ids of each contact, normalised so that ``rod_i <= rod_j``.
    point : (K, 3) float64
        Contact point (midpoint of the two closest points), in the rod set's units.
    gap : (K,) float64
        Surface gap in the rod set's units; negative means penetration.
    """

    rod_i: np.ndarray
    rod_j: np.ndarray
    point: np.ndarray
    gap: np.ndarray

    def __post_init__(self) -> None:
        self.rod_i = _int_array(self.rod_i, "contacts.rod_i").reshape(-1)
        self.rod_j = _int_array(self.rod_j, "contacts.rod_j").reshape(-1)
        self.point = _float_array(self.point, "contacts.point")
        self.gap = _float_array(self.gap, "contacts.gap").reshape(-1)
        if self.point.size == 0:
            self.point = self.point.reshape(0, 3)
        K = self.rod_i.shape[0]
        if self.rod_j.shape != (K,) or self.point.shape != (K, 3) or self.gap.shape != (K,):
            raise _fail(
                f"contacts arrays disagree: rod_i {self.rod_i.shape}, rod_j {self.rod_j.shape}, "
                f"point {self.point.shape}, gap {self.gap.shape}; expected (K,), (K,), (K,3), (K,)")
        _check_finite(self.point, "contacts.point")
        _check_finite(self.gap, "contacts.gap")
        if K and np.any(self.rod_i > self.rod_j):
            lo = np.minimum(self.rod_i, self.rod_j)
            hi = np.maximum(self.rod_i, self.rod_j)
            self.rod_i, self.rod_j = lo, hi

    def __len__(self) -> int:
        """Number of contacts K."""
        return int(self.rod_i.shape[0])

    def __repr__(self) -> str:
        return f"Contacts(K={len(self)})"

    def copy(self) -> "Contacts":
        """Deep copy (new arrays)."""
        return Contacts(self.rod_i.copy(), self.rod_j.copy(), self.point.copy(), self.gap.copy())

    @classmethod
    def empty(cls) -> "Contacts":
        """A contact list with K = 0."""
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros(0))


# ----------------------------------------------------------------------------------------------
# RodSet
# ----------------------------------------------------------------------------------------------

@dataclass(eq=False)
class RodSet:
    """N polyline rods with per-rod radii, stored as concatenated vertices plus offsets.

    Attributes
    ----------
    points : (V, 3) float64
        All vertices in ``units``, rods concatenated.
    offsets : (N+1,) int64
        Rod ``r`` owns ``points[offsets[r]:offsets[r+1]]``; ``offsets[0] == 0``,
        ``offsets[-1] == V`` and every rod has at least 2 vertices.
    radii : (N,) float64
        Per-rod radius in ``units``; must be positive.
    units : str
        One of ``"m"``, ``"mm"``, ``"um"``, ``"voxel"`` (see :data:`UNITS`).
    rest_points : (V, 3) float64 or None
        Optional stress-free shape, same layout as ``points``, in ``units``.
    velocities : (V, 3) float64 or None
        Optional vertex velocities in ``units`` per second.
    contacts : Contacts or None
        Optional rod-rod contacts of this configuration (points and gaps in ``units``).
    box : (2, 3) float64 or None
        Optional container, lower corner then upper corner, in ``units``.
    attrs : dict
        JSON-serialisable metadata (seed, parameters, provenance).

    Notes
    -----
    Construction converts dtypes and calls :meth:`validate`; assigning attributes afterwards
    is allowed, and :meth:`save` validates again before writing.
    """

    points: np.ndarray
    offsets: np.ndarray
    radii: np.ndarray
    units: str = "m"
    rest_points: np.ndarray | None = None
    velocities: np.ndarray | None = None
    contacts: Contacts | None = None
    box: np.ndarray | None = None
    attrs: dict = field(default_factory=dict)

    # -- construction / validation -------------------------------------------------------------

    def __post_init__(self) -> None:
        self.points = _float_array(self.points, "points")
        if self.points.size == 0 and self.points.ndim == 1:
            self.points = self.points.reshape(0, 3)
        self.offsets = _int_array(self.offsets, "offsets")
        self.radii = _float_array(self.radii, "radii")
        if self.radii.ndim == 0:  # a scalar radius applies to every rod
            n = max(self.offsets.shape[0] - 1, 0) if self.offsets.ndim == 1 else 0
            self.radii = np.full(n, float(self.radii))
        if self.rest_points is not None:
            self.rest_points = _float_array(self.rest_points, "rest_points")
        if self.velocities is not None:
            self.velocities = _float_array(self.velocities, "velocities")
        if self.box is not None:
            self.box = _float_array(self.box, "box")
        if self.contacts is not None and not isinstance(self.contacts, Contacts):
            raise _fail(f"contacts must be a Contacts object or None, got {type(self.contacts).__name__}")
        if self.attrs is None:
            self.attrs = {}
        self.validate()

    def validate(self) -> None:
        """Check shapes, values and metadata; raise :class:`RodwarpError` on the first problem.

        Raises
        ------
        RodwarpError
            Empty set, bad offsets, inconsistent shapes, NaN/inf, non-positive radii, unknown
            units, an inverted box, contacts referring to missing rods, or non-JSON attrs.
        """
        _check_units(self.units)
        p, o, r = self.points, self.offsets, self.radii
        if p.ndim != 2 or p.shape[1] != 3:
            raise _fail(f"points must have shape (V, 3), got {p.shape}")
        if o.ndim != 1:
            raise _fail(f"offsets must be 1-D (N+1,), got shape {o.shape}")
        V = p.shape[0]
        if o.shape[0] < 2 or V == 0:
            raise _fail("rod set is empty; give at least one rod with 2 or more vertices")
        N = o.shape[0] - 1
        if o[0] != 0:
            raise _fail(f"offsets must start at 0, got {o[0]}")
        if o[-1] != V:
            raise _fail(f"offsets must end at the vertex count {V}, got {o[-1]}")
        counts = np.diff(o)
        if np.any(counts < 2):
            bad = int(np.flatnonzero(counts < 2)[0])
            raise _fail(f"rod {bad} has {counts[bad]} vertices; offsets must increase by at least 2 "
                        f"(each rod needs 2 or more vertices)")
        if r.shape != (N,):
            raise _fail(f"radii must have shape ({N},) (one per rod), got {r.shape}")
        _check_finite(p, "points")
        _check_finite(r, "radii")
        if np.any(r <= 0):
            bad = int(np.flatnonzero(r <= 0)[0])
            raise _fail(f"radius of rod {bad} is {float(r[bad])!r}; radii must be positive")
        for name in ("rest_points", "velocities"):
            a = getattr(self, name)
            if a is None:
                continue
            if a.shape != p.shape:
                raise _fail(f"{name} must have the same shape as points {p.shape}, got {a.shape}")
            _check_finite(a, name)
        if self.box is not None:
            b = self.box
            if b.shape != (2, 3):
                raise _fail(f"box must have shape (2, 3) (lower corner, upper corner), got {b.shape}")
            _check_finite(b, "box")
            if np.any(b[0] >= b[1]):
                raise _fail(f"box lower corner {b[0].tolist()} must be below upper corner {b[1].tolist()} "
                            f"on every axis")
        c = self.contacts
        if c is not None:
            if not isinstance(c, Contacts):
                raise _fail(f"contacts must be a Contacts object or None, got {type(c).__name__}")
            if len(c):
                lo = min(int(c.rod_i.min()), int(c.rod_j.min()))
                hi = max(int(c.rod_i.max()), int(c.rod_j.max()))
                if lo < 0 or hi >= N:
                    raise _fail(f"contacts refer to rod {lo if lo < 0 else hi} but the set has rods 0..{N - 1}")
        if not isinstance(self.attrs, dict):
            raise _fail(f"attrs must be a dict, got {type(self.attrs).__name__}")
        try:
            json.dumps(self.attrs, default=_json_default)
        except (TypeError, ValueError) as e:
            raise _fail(f"attrs are not JSON-serialisable ({e}); keep to str, int, float, bool, list, dict") from None

    def __repr__(self) -> str:
        extra = [n for n in ("rest_points", "velocities", "box") if getattr(self, n) is not None]
        if self.contacts is not None:
            extra.append(f"contacts={len(self.contacts)}")
        more = (", " + ", ".join(extra)) if extra else ""
        return f"RodSet(n_rods={self.n_rods}, n_vertices={self.n_vertices}, units={self.units!r}{more})"

    # -- sizes and indexing --------------------------------------------------------------------

    @property
    def n_rods(self) -> int:
        """Number of rods N."""
        return int(self.offsets.shape[0] - 1)

    @property
    def n_vertices(self) -> int:
        """Number of vertices V (all rods)."""
        return int(self.points.shape[0])

    @property
    def n_segments(self) -> int:
        """Number of segments S = V - N (joins between rods are not segments)."""
        return self.n_vertices - self.n_rods

    @property
    def vertex_counts(self) -> np.ndarray:
        """(N,) int64 vertices per rod."""
        return np.diff(self.offsets)

    @property
    def rod_index(self) -> np.ndarray:
        """(V,) int64 rod id of each vertex."""
        return np.repeat(np.arange(self.n_rods, dtype=np.int64), self.vertex_counts)

    @property
    def diameters(self) -> np.ndarray:
        """(N,) float64 rod diameters (``2 * radii``) in ``units``."""
        return 2.0 * self.radii

    def rod(self, i: int) -> np.ndarray:
        """Vertices of rod ``i`` as a view into :attr:`points`.

        Parameters
        ----------
        i : int
            Rod id, ``-N <= i < N`` (negative counts from the end).

        Returns
        -------
        (n_i, 3) float64 view, in ``units``.
        """
        N = self.n_rods
        try:
            j = int(i)
        except (TypeError, ValueError):
            raise _fail(f"rod index must be an integer, got {i!r}") from None
        if not -N <= j < N:
            raise _fail(f"rod index {i} out of range; the set has rods 0..{N - 1}")
        j %= N
        return self.points[self.offsets[j]:self.offsets[j + 1]]

    # -- geometry ------------------------------------------------------------------------------

    def _segment_mask(self) -> np.ndarray:
        """(V-1,) bool: True where vertex k and k+1 belong to the same rod."""
        mask = np.ones(self.n_vertices - 1, dtype=bool)
        mask[self.offsets[1:-1] - 1] = False
        return mask

    def segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All segments, skipping the joins between consecutive rods.

        Returns
        -------
        starts : (S, 3) float64
            Segment start vertices, in ``units``.
        ends : (S, 3) float64
            Segment end vertices, in ``units``.
        rod_of_segment : (S,) int64
            Rod id of each segment. ``S == n_segments == V - N``; segments of a rod are
            contiguous and in vertex order.
        """
        m = self._segment_mask()
        return self.points[:-1][m], self.points[1:][m], self.rod_index[:-1][m]

    def segment_lengths(self) -> np.ndarray:
        """(S,) float64 segment lengths in ``units``, in the order of :meth:`segments`."""
        m = self._segment_mask()
        return np.linalg.norm(np.diff(self.points, axis=0)[m], axis=1)

    def rod_lengths(self) -> np.ndarray:
        """(N,) float64 polyline arc length of each rod in ``units``."""
        seg_off = self.offsets[:-1] - np.arange(self.n_rods)
        return np.add.reduceat(self.segment_lengths(), seg_off)

    def bounding_box(self) -> np.ndarray:
        """(2, 3) float64 axis-aligned box (lower, upper) enclosing all rods including radii, in ``units``."""
        r = np.repeat(self.radii, self.vertex_counts)[:, None]
        return np.stack([(self.points - r).min(axis=0), (self.points + r).max(axis=0)])

    # -- constructors --------------------------------------------------------------------------

    @classmethod
    def from_polylines(cls, polylines: Sequence, radii, units: str = "m", **kw) -> "RodSet":
        """Build a set from a list of polylines.

        Parameters
        ----------
        polylines : sequence of array-like (n_i, 3)
            Vertices of each rod in ``units``; each rod needs ``n_i >= 2``.
        radii : float or array-like (N,)
            Radius of every rod (scalar) or of each rod, in ``units``.
        units : str
            Length unit of coordinates and radii.
        **kw
            Other :class:`RodSet` fields (``rest_points``, ``velocities``, ``contacts``, ``box``, ``attrs``).

        Returns
        -------
        RodSet
        """
        polys = []
        for k, pl in enumerate(polylines):
            a = _float_array(pl, f"polyline {k}")
            if a.ndim != 2 or a.shape[1] != 3:
                raise _fail(f"polyline {k} must have shape (n, 3), got {a.shape}")
            if a.shape[0] < 2:
                raise _fail(f"polyline {k} has {a.shape[0]} vertices; each rod needs 2 or more")
            polys.append(a)
        if not polys:
            raise _fail("rod set is empty; pass at least one polyline")
        offsets = np.zeros(len(polys) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([a.shape[0] for a in polys])
        r = _float_array(radii, "radii")
        if r.ndim == 0:
            r = np.full(len(polys), float(r))
        return cls(np.concatenate(polys), offsets, r, units=units, **kw)

    @classmethod
    def from_straight(cls, centers, directions, lengths, radii, n_vertices: int = 10, units: str = "m",
                      **kw) -> "RodSet":
        """Build straight rods with evenly spaced vertices.

        Parameters
        ----------
        centers : array-like (N, 3)
            Rod midpoints in ``units``.
        directions : array-like (N, 3)
            Rod axes (any non-zero length; normalised here).
        lengths : float or array-like (N,)
            End-to-end length of each rod in ``units``.
        radii : float or array-like (N,)
            Rod radii in ``units``.
        n_vertices : int
            Vertices per rod (>= 2), spaced ``length / (n_vertices - 1)`` apart.
        units : str
            Length unit.
        **kw
            Other :class:`RodSet` fields (``box``, ``attrs``, ...).

        Returns
        -------
        RodSet
            Rod ``i`` runs from ``c_i - L_i/2 d_i`` to ``c_i + L_i/2 d_i``.
        """
        c = _float_array(centers, "centers")
        d = _float_array(directions, "directions")
        if c.ndim == 1 and c.shape == (3,):
            c = c[None]
        if d.ndim == 1 and d.shape == (3,):
            d = np.broadcast_to(d, c.shape)
        if c.ndim != 2 or c.shape[1] != 3:
            raise _fail(f"centers must have shape (N, 3), got {c.shape}")
        if d.shape != c.shape:
            raise _fail(f"directions must have the same shape as centers {c.shape}, got {d.shape}")
        N = c.shape[0]
        if N == 0:
            raise _fail("rod set is empty; pass at least one center")
        if isinstance(n_vertices, bool) or int(n_vertices) != n_vertices or n_vertices < 2:
            raise _fail(f"n_vertices must be an integer >= 2, got {n_vertices!r}")
        n = int(n_vertices)
        _check_finite(c, "centers")
        _check_finite(d, "directions")
        norm = np.linalg.norm(d, axis=1)
        if np.any(norm == 0):
            raise _fail(f"direction of rod {int(np.flatnonzero(norm == 0)[0])} is zero; give a non-zero axis")
        d = d / norm[:, None]
        L = _float_array(lengths, "lengths")
        L = np.full(N, float(L)) if L.ndim == 0 else L
        if L.shape != (N,):
            raise _fail(f"lengths must be a scalar or shape ({N},), got {L.shape}")
        _check_finite(L, "lengths")
        if np.any(L <= 0):
            raise _fail(f"rod lengths must be positive, got {float(L[L <= 0][0])!r}")
        r = _float_array(radii, "radii")
        r = np.full(N, float(r)) if r.ndim == 0 else r
        t = np.linspace(-0.5, 0.5, n)
        t = 0.5 * (t - t[::-1])  # exactly antisymmetric parameters: endpoints symmetric about the centre
        pts = c[:, None, :] + (t[None, :, None] * L[:, None, None]) * d[:, None, :]
        offsets = np.arange(N + 1, dtype=np.int64) * n
        return cls(pts.reshape(-1, 3), offsets, r, units=units, **kw)

    # -- derived sets --------------------------------------------------------------------------

    def copy(self) -> "RodSet":
        """Deep copy: new arrays, new contacts, deep-copied attrs."""
        return RodSet(
            self.points.copy(), self.offsets.copy(), self.radii.copy(), units=self.units,
            rest_points=None if self.rest_points is None else self.rest_points.copy(),
            velocities=None if self.velocities is None else self.velocities.copy(),
            contacts=None if self.contacts is None else self.contacts.copy(),
            box=None if self.box is None else self.box.copy(),
            attrs=_copy.deepcopy(self.attrs))

    def with_points(self, points, velocities=None) -> "RodSet":
        """A new set with new vertex positions (and velocities), sharing everything else.

        Parameters
        ----------
        points : array-like (V, 3)
            New vertices in ``units``, same layout as :attr:`points`.
        velocities : array-like (V, 3) or None
            New vertex velocities in ``units``/s; None means the new set has no velocities.

        Returns
        -------
        RodSet
            Shares ``offsets``, ``radii``, ``rest_points`` and ``box`` arrays with this set; ``attrs``
            is a shallow copy. ``contacts`` is not carried over (it described the old positions).
        """
        return RodSet(points, self.offsets, self.radii, units=self.units, rest_points=self.rest_points,
                      velocities=velocities, contacts=None, box=self.box, attrs=dict(self.attrs))

    def to_units(self, units: str, *, voxel_size: float | None = None) -> "RodSet":
        """Convert to another length unit.

        Parameters
        ----------
        units : str
            Target unit, one of :data:`UNITS`.
        voxel_size : float, optional
            Metres per voxel; required (and only allowed) when converting to or from ``"voxel"``.

        Returns
        -------
        RodSet
            New set with points, rest_points, velocities (units/s), radii, box, contact points and
            gaps scaled. Metric conversions scale by exact powers of ten (``m -> mm`` is ``x * 1000``).
        """
        k, div = _unit_scale(self.units, units, voxel_size)
        if k == 1.0 and not div:
            out = self.copy()
            out.units = units
            return out
        c = self.contacts
        if c is not None:
            c = Contacts(c.rod_i.copy(), c.rod_j.copy(), _scale(c.point, k, div), _scale(c.gap, k, div))
        return RodSet(_scale(self.points, k, div), self.offsets.copy(), _scale(self.radii, k, div), units=units,
                      rest_points=_scale(self.rest_points, k, div), velocities=_scale(self.velocities, k, div),
                      contacts=c, box=_scale(self.box, k, div), attrs=_copy.deepcopy(self.attrs))

    # -- I/O -----------------------------------------------------------------------------------

    def _meta(self) -> dict:
        return {"format": FORMAT_NAME, "format_version": FORMAT_VERSION, "units": self.units,
                "n_rods": self.n_rods, "n_vertices": self.n_vertices, "attrs": self.attrs}

    def _arrays(self) -> dict[str, np.ndarray]:
        arrays = {"points": self.points, "offsets": self.offsets, "radii": self.radii}
        for name in _OPTIONAL_KEYS:
            if getattr(self, name) is not None:
                arrays[name] = getattr(self, name)
        if self.contacts is not None:
            c = self.contacts
            arrays.update(contact_rod_i=c.rod_i, contact_rod_j=c.rod_j, contact_point=c.point, contact_gap=c.gap)
        return arrays

    def save(self, path: str | os.PathLike) -> Path:
        """Validate and write the set atomically; the format follows the suffix.

        Parameters
        ----------
        path : path-like
            ``*.npz`` (compressed NumPy archive), ``*.zarr`` (zarr group directory) or ``*.csv``
            (``rod,x,y,z,radius`` only; contacts, velocities, rest shape, box, units and attrs are
            not stored). An existing file or directory is replaced.

        Returns
        -------
        Path
            The written path.
        """
        self.validate()
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix == ".npz":
            meta = json.dumps(self._meta(), default=_json_default)
            with atomic_path(path) as tmp:
                with open(tmp, "wb") as fh:  # a file object stops NumPy from appending ".npz"
                    np.savez_compressed(fh, meta=np.array(meta), **self._arrays())
        elif suffix == ".zarr":
            import zarr

            meta = json.loads(json.dumps(self._meta(), default=_json_default))
            with atomic_path(path, directory=True) as tmp:
                g = zarr.open_group(str(tmp), mode="w")
                for name, arr in self._arrays().items():
                    if hasattr(g, "create_array"):
                        g.create_array(name, data=arr)
                    else:  # zarr 2
                        g.array(name, arr)
                g.attrs.update(meta)
        elif suffix == ".csv":
            self.to_csv(path)
        else:
            raise _fail(f"unsupported file type {path.suffix or '(none)'!r} for {path}; "
                        f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
        return path

    def to_csv(self, path: str | os.PathLike) -> Path:
        """Write ``rod,x,y,z,radius`` (one row per vertex, rods 0..N-1 in order) atomically.

        Parameters
        ----------
        path : path-like
            Destination. Values use ``%.17g`` so floats round-trip exactly. Coordinates and
            radius are in ``self.units``, which the CSV does not record.

        Returns
        -------
        Path
            The written path.
        """
        self.validate()
        path = Path(path)
        table = np.empty((self.n_vertices, 5), dtype=np.float64)
        table[:, 0] = self.rod_index
        table[:, 1:4] = self.points
        table[:, 4] = np.repeat(self.radii, self.vertex_counts)
        with atomic_path(path) as tmp:
            with open(tmp, "w", newline="") as fh:
                fh.write("rod,x,y,z,radius\n")
                np.savetxt(fh, table, fmt=["%d", "%.17g", "%.17g", "%.17g", "%.17g"], delimiter=",")
        return path

    @classmethod
    def load(cls, path: str | os.PathLike, *, radius: float | None = None, diameter: float | None = None,
             units: str | None = None) -> "RodSet":
        """Read a rod set; same as :func:`rodwarp.rodset.load`."""
        return load(path, radius=radius, diameter=diameter, units=units)


# ----------------------------------------------------------------------------------------------
# loading
# ----------------------------------------------------------------------------------------------

def load(path: str | os.PathLike, *, radius: float | None = None, diameter: float | None = None,
         units: str | None = None) -> RodSet:
    """Read a rod set from ``.npz``, ``.zarr`` or ``.csv``.

    Parameters
    ----------
    path : path-like
        File (``.npz``, ``.csv``) or zarr group directory (``.zarr`` name or containing ``zarr.json``/``.zgroup``).
    radius, diameter : float, optional
        Rod radius or diameter in the file's units, for CSV files without a ``radius`` column
        (give one, not both). Ignored when the file carries radii.
    units : str, optional
        CSV: the unit the coordinates are in (default ``"m"``). npz/zarr: convert the stored
        set to this unit (metric units only; use :meth:`RodSet.to_units` for voxels).

    Returns
    -------
    RodSet

    Raises
    ------
    RodwarpError
        Missing file, unknown type, a file not written by rodwarp, or invalid content.
    """
    path = Path(path)
    if not path.exists():
        raise _fail(f"no such file: {path}; check the path")
    if radius is not None and diameter is not None:
        raise _fail("pass either radius or diameter, not both")
    if units is not None:
        _check_units(units)
    suffix = path.suffix.lower()
    is_zarr_dir = path.is_dir() and (suffix == ".zarr" or (path / "zarr.json").exists()
                                     or (path / ".zgroup").exists())
    if is_zarr_dir:
        rods = _load_zarr(path)
    elif path.is_dir():
        raise _fail(f"{path} is a directory but not a zarr group; pass a {', '.join(SUPPORTED_SUFFIXES)} path")
    elif suffix == ".npz":
        rods = _load_npz(path)
    elif suffix == ".csv":
        if diameter is not None:
            radius = _positive(diameter, "diameter") / 2.0
        elif radius is not None:
            radius = _positive(radius, "radius")
        return _load_csv(path, radius, units or "m")
    else:
        raise _fail(f"unsupported file type {path.suffix or '(none)'!r} for {path}; "
                    f"use one of {', '.join(SUPPORTED_SUFFIXES)}")
    if units is not None and units != rods.units:
        try:
            rods = rods.to_units(units)
        except RodwarpError as e:
            raise _fail(f"{path}: {e}") from None
    return rods


def _positive(v, name: str) -> float:
    try:
        f = float(v)
    except (TypeError, ValueError):
        raise _fail(f"{name} must be a positive number, got {v!r}") from None
    if not (math.isfinite(f) and f > 0):
        raise _fail(f"{name} must be a positive number, got {v!r}")
    return f


def _parse_meta(meta, path: Path) -> dict:
    if isinstance(meta, str):
        try:
            meta = json.loads(meta)
        except json.JSONDecodeError as e:
            raise _fail(f"{path}: 'meta' is not valid JSON ({e}); the file is damaged or not a rodwarp rod set") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise _fail(f"{path} is not a rodwarp rod set (no format {FORMAT_NAME!r} in its metadata); "
                    f"build one with RodSet.from_polylines(...) and save it")
    version = meta.get("format_version")
    if not isinstance(version, int) or version > FORMAT_VERSION or version < 1:
        raise _fail(f"{path} has rod-set format_version {version!r}; this rodwarp reads version "
                    f"{FORMAT_VERSION} or older, so upgrade rodwarp")
    return meta


def _assemble(arrays: dict, meta: dict, path: Path) -> RodSet:
    for key in ("points", "offsets", "radii"):
        if key not in arrays:
            raise _fail(f"{path} lacks the {key!r} array; the file is damaged or incomplete")
    present = [k for k in _CONTACT_KEYS if k in arrays]
    if present and len(present) != len(_CONTACT_KEYS):
        missing = [k for k in _CONTACT_KEYS if k not in arrays]
        raise _fail(f"{path} has {', '.join(present)} but lacks {', '.join(missing)}; the file is damaged")
    contacts = None
    try:
        if present:
            contacts = Contacts(*(arrays[k] for k in _CONTACT_KEYS))
        attrs = meta.get("attrs") or {}
        return RodSet(arrays["points"], arrays["offsets"], arrays["radii"], units=meta.get("units", "m"),
                      rest_points=arrays.get("rest_points"), velocities=arrays.get("velocities"),
                      contacts=contacts, box=arrays.get("box"), attrs=attrs)
    except RodwarpError as e:
        raise _fail(f"{path}: {e}") from None


def _load_npz(path: Path) -> RodSet:
    import zipfile

    try:
        with np.load(path, allow_pickle=False) as z:
            if "meta" not in z.files:
                raise _fail(f"{path} has no 'meta' entry, so it was not written by rodwarp; "
                            f"build a RodSet from its arrays and save it")
            meta = _parse_meta(str(z["meta"][()]), path)
            arrays = {k: z[k] for k in z.files if k != "meta"}
    except RodwarpError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as e:
        raise _fail(f"cannot read {path} as npz ({type(e).__name__}: {e}); the file is damaged or not npz") from None
    return _assemble(arrays, meta, path)


def _load_zarr(path: Path) -> RodSet:
    import zarr

    try:
        g = zarr.open_group(str(path), mode="r")
        meta_raw = dict(g.attrs)
        names = list(g.array_keys())
        arrays = {k: np.asarray(g[k][...]) for k in names}
    except Exception as e:  # zarr raises many types for unreadable stores
        raise _fail(f"cannot read {path} as a zarr group ({type(e).__name__}: {e})") from None
    if "format" not in meta_raw:
        raise _fail(f"{path} has no rodwarp metadata in its group attributes, so it was not written by rodwarp; "
                    f"build a RodSet from its arrays and save it")
    meta = _parse_meta(meta_raw, path)
    return _assemble(arrays, meta, path)


# -- CSV -------------------------------------------------------------------------------------

class _NeedSlowPath(Exception):
    """The fast CSV reader saw a problem; re-read line by line to report it precisely."""


def _load_csv(path: Path, radius: float | None, units: str) -> RodSet:
    name = str(path)
    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            header = next(csv.reader(fh), None)
    except UnicodeDecodeError as e:
        raise _fail(f"{name}: not UTF-8 text ({e}); save the CSV as UTF-8") from None
    if header is None:
        raise _fail(f"{name} is empty; expected a header line rod,x,y,z[,radius]")
    cols = [h.strip().lower() for h in header]
    missing = [c for c in ("rod", "x", "y", "z") if c not in cols]
    if missing:
        raise _fail(f"{name} line 1: header lacks column(s) {', '.join(missing)}; "
                    f"the header must contain rod,x,y,z (optionally radius), got {','.join(header)!r}")
    want = ["rod", "x", "y", "z"] + (["radius"] if "radius" in cols else [])
    for c in want:
        if cols.count(c) > 1:
            raise _fail(f"{name} line 1: column {c!r} appears {cols.count(c)} times; keep one")
    if "radius" not in cols and radius is None:
        raise _fail(f"{name}: CSV has no radius column; pass --diameter (or radius=/diameter= in Python)")
    usecols = [cols.index(c) for c in want]

    try:
        data = _csv_fast(path, usecols)
        return _csv_build(data, None, want, radius, units, name)
    except _NeedSlowPath:
        pass
    data, lines = _csv_slow(path, usecols, want, name)
    try:
        return _csv_build(data, lines, want, radius, units, name)
    except _NeedSlowPath:  # pragma: no cover - slow path always has line numbers
        raise _fail(f"{name}: malformed CSV; check it has one numeric row per vertex") from None


def _csv_fast(path: Path, usecols: list[int]) -> np.ndarray:
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            data = np.loadtxt(path, delimiter=",", skiprows=1, usecols=usecols, ndmin=2, comments=None,
                              quotechar='"', dtype=np.float64, encoding="utf-8-sig")
    except (ValueError, IndexError, UnicodeDecodeError):
        raise _NeedSlowPath from None
    if data.size and not np.all(np.isfinite(data)):
        raise _NeedSlowPath
    return data.reshape(-1, len(usecols))


def _csv_slow(path: Path, usecols: list[int], names: list[str], fname: str) -> tuple[np.ndarray, np.ndarray]:
    rows, lines = [], []
    with open(path, newline="", encoding="utf-8-sig") as fh:
        reader = csv.reader(fh)
        next(reader, None)
        for row in reader:
            line = reader.line_num
            if not row or all(not f.strip() for f in row):
                continue
            vals = []
            for c, n in zip(usecols, names):
                if c >= len(row):
                    raise _fail(f"{fname} line {line}: has {len(row)} fields but column {n!r} is field {c + 1}; "
                                f"fill in the missing values")
                s = row[c].strip()
                try:
                    v = float(s)
                except ValueError:
                    raise _fail(f"{fname} line {line} column {n!r}: {s!r} is not a number") from None
                if not math.isfinite(v):
                    raise _fail(f"{fname} line {line} column {n!r}: value {s!r} is not finite; remove or fix the row")
                vals.append(v)
            rows.append(vals)
            lines.append(line)
    data = np.array(rows, dtype=np.float64).reshape(-1, len(usecols))
    return data, np.array(lines, dtype=np.int64)


def _csv_build(data: np.ndarray, lines: np.ndarray | None, names: list[str], radius: float | None, units: str,
               fname: str) -> RodSet:
    """Group CSV rows into rods. With ``lines`` None any problem raises _NeedSlowPath."""

    def fail(row: int, msg: str) -> RodwarpError:
        if lines is None:
            raise _NeedSlowPath
        return _fail(f"{fname} line {lines[row]}: {msg}")

    if data.shape[0] == 0:
        raise _fail(f"{fname}: rod set is empty (header but no rows); add one row per vertex")
    ids_f = data[:, 0]
    bad = np.flatnonzero((ids_f != np.round(ids_f)) | (np.abs(ids_f) > 2.0 ** 53))
    if bad.size:
        raise fail(int(bad[0]), f"rod id {float(ids_f[bad[0]])!r} is not an integer")
    ids = ids_f.astype(np.int64)
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    block_ids = ids[starts]
    uniq, first = np.unique(block_ids, return_index=True)
    if uniq.size != block_ids.size:
        seen = np.zeros(block_ids.size, dtype=bool)
        seen[first] = True
        k = int(np.flatnonzero(~seen)[0])
        rid = int(block_ids[k])
        prev = int(starts[np.flatnonzero(block_ids[:k] == rid)[-1]])
        raise fail(int(starts[k]), f"rows of rod {rid} are not contiguous (rod {rid} also appears from line "
                                   f"{lines[prev] if lines is not None else '?'}); sort rows by rod, keeping "
                                   f"vertex order within each rod")
    offsets = np.r_[starts, ids.shape[0]].astype(np.int64)
    counts = np.diff(offsets)
    if np.any(counts < 2):
        k = int(np.flatnonzero(counts < 2)[0])
        raise fail(int(starts[k]), f"rod {int(block_ids[k])} has only 1 vertex; each rod needs 2 or more rows")
    if "radius" in names:
        rad = data[:, 4]
        r_rod = rad[starts]
        diff = np.flatnonzero(rad != np.repeat(r_rod, counts))
        if diff.size:
            row = int(diff[0])
            k = int(np.searchsorted(starts, row, side="right") - 1)
            raise fail(row, f"radius {float(rad[row])!r} differs from {float(r_rod[k])!r} on the first row of rod "
                            f"{int(block_ids[k])}; radius must be constant per rod")
        nonpos = np.flatnonzero(r_rod <= 0)
        if nonpos.size:
            k = int(nonpos[0])
            raise fail(int(starts[k]), f"radius of rod {int(block_ids[k])} is {float(r_rod[k])!r}; radii must be positive")
    else:
        r_rod = np.full(block_ids.size, float(radius))
    attrs = {}
    if not np.array_equal(block_ids, np.arange(block_ids.size)):
        attrs["source_rod_ids"] = block_ids.tolist()
    try:
        return RodSet(np.ascontiguousarray(data[:, 1:4]), offsets, r_rod, units=units, attrs=attrs)
    except RodwarpError as e:
        raise _fail(f"{fname}: {e}") from None
