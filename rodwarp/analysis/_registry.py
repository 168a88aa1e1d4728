"""The field registry: one row per local field of ``rodwarp analyze``.

A row (:class:`FieldSpec`) is all that a field needs to appear everywhere: the array in
``fields.zarr`` (and the attribute of :class:`~rodwarp.analysis.Fields`), its mean in
``summary.json``, its panels in the figures (histograms, slices, z-profiles) and its line in
``rodwarp analyze --help``.  Adding a field is adding a row to :data:`FIELDS`; nothing else
names the fields one by one.  The definitions, their exact clipping and their units are in
``docs/fields.md``.

Columns
    ``name``     array name (``fields.zarr``, ``Fields.<name>``, z-profiles, histograms)
    ``kernel``   its value in every computed ball, from :class:`BallMeasures` (what the Warp
                 kernels of :mod:`rodwarp.kernels.fields` measured there)
    ``units``    ``"1"`` for dimensionless, else what the field counts
    ``reducer``  ``"mean"``: ``summary.json`` holds the mean over the valid voxels; None: the
                 field is stored but not summarised
    ``figure``   panels it gets: any of ``"histogram"``, ``"slices"``, ``"zprofile"``
    ``summary``  the key of that mean in ``summary.json``
    ``symbol``, ``title``, ``doc``  figure label (mathtext), short name, one-line definition

This module imports no Warp: the statistics and figures read the registry on any machine.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Callable

import numpy as np

__all__ = ["FieldSpec", "BallMeasures", "FIELDS", "field_names", "field_spec", "fields_with", "fields_help"]

#: every panel kind a field can have
PANELS = ("histogram", "slices", "zprofile")


@dataclass
class BallMeasures:
    """What the Warp kernels measured in each computed ball (arrays over the computed voxels).

    Lengths are in the rod set's units.  The first five come from one pass of
    ``rodwarp.kernels.fields.ball_fields`` over the clipped parts of every ball; point counts
    (:meth:`count_points`) launch ``count_contacts_in_ball`` on any set of points.

    Attributes
    ----------
    rods : ndarray of int
        Distinct rods with a clipped part in the ball.
    length : ndarray
        Sum of the clipped lengths (length).
    volume : ndarray
        Clipped rod volume, the sum of (pi d^2 / 4) L over the clipped parts (length^3).
    order : ndarray
        Largest eigenvalue of the clipped-length-weighted Q tensor (NaN in an empty ball).
    entanglement : ndarray
        Sum of |G| over the clipped part pairs of distinct rods.
    ball_volume : float
        4/3 pi R^3 (length^3).
    rod_volume : float
        Volume pi d^2 l / 4 of a mean rod (length^3).
    rod_set : RodSet
        The analysed rods.
    contacts : Contacts
        The contacts of the packing (one per touching rod pair, with its contact point).
    count_points : callable(points (P, 3)) -> ndarray of int
        Points within R of each computed ball's centre.
    """

    rods: np.ndarray
    length: np.ndarray
    volume: np.ndarray
    order: np.ndarray
    entanglement: np.ndarray
    ball_volume: float
    rod_volume: float
    rod_set: object
    contacts: object
    count_points: Callable[[np.ndarray], np.ndarray]

    @functools.cached_property
    def contact_points(self) -> np.ndarray:
        """Contact points of the packing in each ball (one per contact)."""
        return self.count_points(np.asarray(self.contacts.point, dtype=np.float64))

    @functools.cached_property
    def rho(self) -> float:
        """Rods per unit volume, from the mean volume fraction of the occupied balls (a partly
        empty container does not dilute it): mean phi / rod volume (1 / length^3)."""
        occupied = self.rods > 0
        mean_phi = float(np.mean(self.volume[occupied] / self.ball_volume)) if occupied.any() else 0.0
        return mean_phi / self.rod_volume

    @property
    def Z(self) -> float:
        """Contacts per rod, 2 K / N."""
        return 2.0 * len(self.contacts) / self.rod_set.n_rods

    @property
    def contact_normalisation(self) -> float:
        """rho Z V_ball / 2: the contact points a ball of the mean packing holds."""
        return self.rho * self.Z * self.ball_volume / 2.0

    def rod_ends(self) -> np.ndarray:
        """(2N, 3) first and last vertex of every rod."""
        o = self.rod_set.offsets
        return np.concatenate([self.rod_set.points[o[:-1]], self.rod_set.points[o[1:] - 1]])


def _contact_density(b: BallMeasures) -> np.ndarray:
    norm = b.contact_normalisation
    # no contact anywhere: the density is 0, not 0 / 0
    return b.contact_points / norm if norm > 0 else np.zeros(len(b.rods))


@dataclass(frozen=True)
class FieldSpec:
    """One row of the field registry (see the module docstring for the columns)."""

    name: str
    kernel: Callable[[BallMeasures], np.ndarray]
    units: str
    reducer: str | None
    figure: tuple[str, ...]
    summary: str | None
    symbol: str
    title: str
    doc: str

    def __post_init__(self) -> None:
        if not self.name.isidentifier() or self.name in ("x", "y", "z"):
            raise ValueError(f"field name {self.name!r} must be an identifier other than x, y, z")
        if self.reducer not in (None, "mean"):
            raise ValueError(f"field {self.name}: reducer must be 'mean' or None, got {self.reducer!r}")
        if (self.reducer is None) != (self.summary is None):
            raise ValueError(f"field {self.name}: a summary key goes with a reducer")
        bad = [p for p in self.figure if p not in PANELS]
        if bad:
            raise ValueError(f"field {self.name}: unknown panels {bad}; use {PANELS}")

    @property
    def label(self) -> str:
        """Axis label: symbol and title."""
        return f"{self.symbol} ({self.title})"


_ALL = PANELS

#: The fields of ``rodwarp analyze``, in the order of files, summaries and figures.
FIELDS: tuple[FieldSpec, ...] = (
    FieldSpec("phi", lambda b: b.volume / b.ball_volume, "1", "mean", _ALL, "mean_phi",
              r"$\phi$", "volume fraction", "clipped rod volume (pi d^2 / 4 per unit length) / ball volume"),
    FieldSpec("S", lambda b: np.where(b.rods > 0, b.order, np.nan), "1", "mean", _ALL, "mean_S",
              r"$S$", "nematic order", "largest eigenvalue of the clipped-length-weighted <(3 u u^T - I) / 2>"),
    FieldSpec("c", _contact_density, "1", "mean", _ALL, "mean_c",
              r"$c$", "contact density", "contact points in the ball / (rho Z V_ball / 2)"),
    FieldSpec("e", lambda b: b.entanglement, "1", "mean", _ALL, "mean_e",
              r"$e$", "entanglement", "sum over pairs of distinct rods of the ACN of their clipped parts"),
    FieldSpec("n", lambda b: b.rods.astype(np.float64), "rods", "mean", ("slices", "zprofile"), "mean_n",
              r"$n$", "rods per ball", "rods with a clipped part in the ball"),
    FieldSpec("contacts", lambda b: b.contact_points.astype(np.float64), "contact points", None, (), None,
              r"$K_{ball}$", "contact points", "contact points of the packing in the ball (raw count behind c)"),
    FieldSpec("n_ends", lambda b: b.count_points(b.rod_ends()).astype(np.float64), "rod ends", "mean", _ALL,
              "mean_n_ends", r"$n_{end}$", "rod ends per ball", "rod ends (first and last vertices) in the ball"),
)

# Everything below reads FIELDS when called, never a copy taken at import: the row is the one
# place a field is defined.

def field_names() -> tuple[str, ...]:
    """Names of the registered fields, in registry order."""
    return tuple(f.name for f in FIELDS)


def field_spec(name: str) -> FieldSpec:
    """The registry row of ``name`` (KeyError for a field that is not registered)."""
    for f in FIELDS:
        if f.name == name:
            return f
    raise KeyError(f"no field {name!r} in the registry; registered: {', '.join(field_names())}")


def fields_with(panel: str | None = None, *, reducer: str | None = None) -> tuple[FieldSpec, ...]:
    """Rows that have figure ``panel`` (and/or the given ``reducer``), in registry order."""
    return tuple(f for f in FIELDS
                 if (panel is None or panel in f.figure) and (reducer is None or f.reducer == reducer))


def fields_help() -> str:
    """One entry per field for ``rodwarp analyze --help``: name, title, units, definition.

    (No square brackets: the help is rendered as rich markup, which would take them as tags.)
    """
    def units(u: str) -> str:
        return "dimensionless" if u == "1" else u

    return "; ".join(f"{f.name}: {f.title} ({units(f.units)}), {f.doc}" for f in FIELDS)
