"""The rod set: one host-side (NumPy) container for simulation, segmentation and analysis.

A :class:`RodSet` holds N polyline rods with all vertices concatenated in one ``(V, 3)``
array and a CSR-style ``offsets`` array, so rod ``r`` owns ``points[offsets[r]:offsets[r+1]]``.
Coordinates, radii, gaps and the box are in ``units`` (``"m"``, ``"mm"``, ``"um"`` or
``"voxel"``); velocities are in ``units`` per second.

Files (:mod:`rodwarp.rodset._formats`): ``.npz`` and ``.zarr`` keep everything (see
``docs/rodset-format.md``); ``.csv`` keeps only ``rod,x,y,z,radius``. Every write is atomic. All
bad input raises
:class:`~rodwarp.errors.RodwarpError` with a one-line message.

This module must not import warp.
"""

from __future__ import annotations

import copy as _copy
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from rodwarp._util import json_safe
from rodwarp.errors import RodwarpTypeError
from rodwarp._util import one_line_error as _fail
from rodwarp.rodset import _formats
from rodwarp.rodset._formats import FORMAT_NAME, FORMAT_VERSION, SUPPORTED_SUFFIXES
from rodwarp.rodset._units import MAX_COORDINATE, UNITS, _scale, _unit_scale, check_units

__all__ = ["UNITS", "FORMAT_NAME", "FORMAT_VERSION", "SUPPORTED_SUFFIXES", "MAX_COORDINATE", "Contacts", "RodSet",
           "load"]




# ----------------------------------------------------------------------------------------------
# small helpers
# ----------------------------------------------------------------------------------------------

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


def _check_magnitude(a: np.ndarray, name: str, unit: str | None, what: str = "length", row: str = "row") -> None:
    """Refuse finite values beyond :data:`MAX_COORDINATE` of ``unit`` (None: the rod set's unit,
    not known here): they are stray or corrupt numbers, and their squares overflow.  ``row``
    names what a row of ``a`` is (``vertex``, ``contact``)."""
    if not (a.size and float(np.max(np.abs(a))) > MAX_COORDINATE):
        return
    bad = np.argwhere(np.abs(a) > MAX_COORDINATE)[0]
    where = f"{row} {bad[0]}"
    u = f" {unit}" if unit else ""
    of = f"'{unit}'" if unit else "the rod set's unit"
    raise _fail(f"{name} hold {float(a[tuple(bad)]):.3g}{u} (first at {where}), too large to be a {what} in {of} "
                f"(|value| <= {MAX_COORDINATE:g}{u}); fix those values, or give the rods' true units")


def _array_like(value, name: str):
    """``value`` unless it is plainly not an array of numbers (a string, a mapping, a set, None)."""
    if value is None or isinstance(value, (str, bytes, dict, set)):
        raise RodwarpTypeError(f"{name} must be numeric (an array of numbers), got {type(value).__name__} "
                        f"{' '.join(repr(value).split())[:60]}")
    return value


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
        _check_magnitude(self.point, "contacts.point", None, row="contact")
        _check_magnitude(self.gap, "contacts.gap", None, row="contact")
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

    #: the type of :attr:`contacts` (what a file's contact arrays are read into)
    contacts_type = Contacts

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
        self.points = _float_array(_array_like(self.points, "points"), "points")
        if self.points.size == 0 and self.points.ndim == 1:
            self.points = self.points.reshape(0, 3)
        self.offsets = _int_array(_array_like(self.offsets, "offsets"), "offsets")
        self.radii = _float_array(_array_like(self.radii, "radii"), "radii")
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
        check_units(self.units)
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
        _check_magnitude(p, "points", self.units, row="vertex")
        _check_magnitude(r, "radii", self.units, row="rod")
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
            speed = name == "velocities"
            _check_magnitude(a, name, self.units + "/s" if speed else self.units, "speed" if speed else "length",
                             row="vertex")
        if self.box is not None:
            b = self.box
            if b.shape != (2, 3):
                raise _fail(f"box must have shape (2, 3) (lower corner, upper corner), got {b.shape}")
            _check_finite(b, "box")
            _check_magnitude(b, "box", self.units, row="corner")
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
            json_safe(self.attrs, finite=False, strict=True)
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
        if polylines is None or isinstance(polylines, (str, bytes, dict, set)):
            raise RodwarpTypeError(f"polylines must be a sequence of (n, 3) vertex arrays, got "
                                   f"{type(polylines).__name__}")
        polys = []
        for k, pl in enumerate(polylines):
            a = _float_array(_array_like(pl, f"polyline {k}"), f"polyline {k}")
            if a.ndim != 2 or a.shape[1] != 3:
                raise _fail(f"polyline {k} must have shape (n, 3), got {a.shape}")
            if a.shape[0] < 2:
                raise _fail(f"polyline {k} has {a.shape[0]} vertices; each rod needs 2 or more")
            polys.append(a)
        if not polys:
            raise _fail("rod set is empty; pass at least one polyline")
        offsets = np.zeros(len(polys) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([a.shape[0] for a in polys])
        r = _float_array(_array_like(radii, "radii"), "radii")
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

    # -- I/O (the formats live in rodwarp.rodset._formats, which knows no class of its own) -----

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
        return _formats.save(self, path)

    def to_csv(self, path: str | os.PathLike) -> Path:
        """Write ``rod,x,y,z,radius`` (one row per vertex, rods 0..N-1 in order) atomically.

        Parameters
        ----------
        path : path-like
            Destination. Values are the shortest decimals that round-trip exactly. Coordinates and
            radius are in ``self.units``, which the CSV does not record.

        Returns
        -------
        Path
            The written path.
        """
        return _formats.save_csv(self, path)

    @classmethod
    def load(cls, path: str | os.PathLike, *, radius: float | None = None, diameter: float | None = None,
             units: str | None = None) -> "RodSet":
        """Read a rod set from ``.npz``, ``.zarr`` or ``.csv``; same as :func:`rodwarp.rodset.load`."""
        return _formats.read(path, cls, radius=radius, diameter=diameter, units=units)


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
    return RodSet.load(path, radius=radius, diameter=diameter, units=units)
