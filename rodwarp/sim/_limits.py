"""The physical ranges of the engine's inputs (SI) and their checks at the API's boundary.

:class:`~rodwarp.sim.ModelBuilder`, :class:`~rodwarp.sim.Model`, :class:`~rodwarp.sim.Material`,
the walls, the control's drive and :class:`~rodwarp.sim.RodSolver` check their arguments here
before any array is built: a wrong kind raises ``TypeError``, a value out of its range a
one-line :class:`~rodwarp.errors.RodwarpError` naming the argument, the range and the unit
(:mod:`rodwarp.arguments`).  The ranges are wide enough for any rod scene on Earth or in a
centrifuge and narrow enough that a typo or a unit slip (1e300, a length in um read as m) is
refused instead of overflowing mid-run.
"""

from __future__ import annotations

import numpy as np

from rodwarp.errors import RodwarpTypeError
from rodwarp.rodset import RodSet
from rodwarp.arguments import instance, real, vector
from rodwarp.validation import MAX_MU  # as ``rodwarp simulate --mu``

__all__ = ["MAX_LENGTH_M", "MIN_RADIUS_M", "MAX_GRAVITY", "MAX_MU", "MAX_DAMPING", "YOUNG_RANGE", "DENSITY_RANGE",
           "MAX_FREQUENCY", "MAX_SPEED", "MODEL_OPTIONS", "check_rods", "check_model_options", "friction",
           "pinned_indices"]

#: largest coordinate, radius or wall offset (m): 1000 km, far beyond any packing
MAX_LENGTH_M = 1e6
#: thinnest rod (m): a nanometre; thinner is not a continuum rod, and far thinner (1e-300 m)
#: makes the rods' masses underflow to zero
MIN_RADIUS_M = 1e-9
#: largest body acceleration (m/s^2): 1e4 g, a laboratory centrifuge's
MAX_GRAVITY = 1e5
#: largest viscous damping rate (1/s): a rate of 1e6 1/s stops any motion within a microsecond
MAX_DAMPING = 1e6
#: Young's modulus (Pa): from a soft gel's (1 Pa) to well above diamond's (1.2e12 Pa)
YOUNG_RANGE = (1.0, 1e13)
#: mass density (kg/m^3): from an aerogel's (1e-2) to well above osmium's (2.3e4)
DENSITY_RANGE = (1e-2, 1e5)
#: highest drive frequency (Hz): ultrasound's
MAX_FREQUENCY = 1e6
#: fastest wall ramp (m/s): ten times the fastest impact the engine is built for
MAX_SPEED = 1e3

#: the options of a Model (keyword arguments of ModelBuilder and Model)
MODEL_OPTIONS = ("gravity", "mu", "damping", "pinned", "contact_distance", "rod_contacts", "extensible", "rod_model",
                 "rolling", "contact_law", "device")


def friction(name: str, mu) -> float:
    """A friction coefficient in [0, :data:`MAX_MU`]."""
    return real(name, mu, ge=0, le=MAX_MU, hint="friction coefficients of real materials are below about 2")


def check_rods(rods) -> RodSet:
    """The rods of a scene, in metres: a :class:`RodSet` with radii in [:data:`MIN_RADIUS_M`,
    :data:`MAX_LENGTH_M`] and coordinates within :data:`MAX_LENGTH_M` of the origin.

    Raises
    ------
    TypeError
        ``rods`` is not a RodSet.
    RodwarpError
        Rods in voxels (no size), or radii or coordinates out of range.
    """
    from rodwarp.errors import RodwarpError

    instance("rods", rods, RodSet, "a RodSet (RodSet.from_polylines(polylines, radii, units='m'))")
    if rods.units == "voxel":
        raise RodwarpError("rods are in voxels; convert with rods.to_units('m', voxel_size=...) first")
    m = rods if rods.units == "m" else rods.to_units("m")
    lo, hi = float(m.radii.min()), float(m.radii.max())
    bad = lo if lo < MIN_RADIUS_M else hi
    real("rods.radii", bad, ge=MIN_RADIUS_M, le=MAX_LENGTH_M, unit="m")
    for name, pts in (("rods.points", m.points), ("rods.rest_points", m.rest_points)):
        if pts is not None:
            real(f"the largest |coordinate| of {name}", float(np.max(np.abs(pts))), le=MAX_LENGTH_M, unit="m",
                 hint="the engine takes rods within 1000 km of the origin")
    return m


def check_model_options(options: dict) -> None:
    """Check the keyword options of a Model (``gravity``, ``mu``, ``damping``, ``pinned``,
    ``contact_distance``): names, kinds and ranges.

    Raises
    ------
    TypeError
        An unknown option, or a value of the wrong kind.
    RodwarpError
        A value out of its range (the message names the option, its range and unit).
    """
    unknown = sorted(set(options) - set(MODEL_OPTIONS))
    if unknown:
        raise RodwarpTypeError(f"unknown model option {', '.join(map(repr, unknown))}; the options are "
                        f"{', '.join(MODEL_OPTIONS)}")
    if "gravity" in options:
        vector("gravity", options["gravity"], unit="m/s^2", limit=MAX_GRAVITY)
    if "mu" in options:
        friction("mu", options["mu"])
    if "damping" in options:
        real("damping", options["damping"], ge=0, le=MAX_DAMPING, unit="1/s")
    if options.get("contact_distance") is not None:
        real("contact_distance", options["contact_distance"], ge=0, le=MAX_LENGTH_M, unit="m",
             hint="a surface gap; the default is a tenth of the thinnest rod's diameter")
    if options.get("pinned") is not None:
        pinned_indices(options["pinned"])
    for name in ("rod_model", "device"):
        if name in options and not isinstance(options[name], str):
            raise RodwarpTypeError(f"{name} must be a string, got {type(options[name]).__name__} {options[name]!r}")


def pinned_indices(pinned, n_vertices: int | None = None) -> np.ndarray:
    """``pinned`` as an int64 array of vertex indices (checked against ``n_vertices`` when given).

    Raises
    ------
    TypeError
        Not an array of whole numbers.
    RodwarpError
        A fractional, non-finite or out-of-range index.
    """
    from rodwarp.errors import RodwarpError

    try:
        arr = np.asarray(pinned)
    except (TypeError, ValueError):
        arr = None
    if arr is None or isinstance(pinned, (str, bytes, dict, set)) or arr.dtype.kind not in "iuf":
        raise RodwarpTypeError(f"pinned must be vertex indices (whole numbers), got {type(pinned).__name__} {pinned!r}")
    arr = arr.ravel()
    if arr.dtype.kind == "f":
        if not (np.all(np.isfinite(arr)) and np.all(arr == np.round(arr))):
            raise RodwarpError(f"pinned must hold whole vertex indices, got {arr[~(arr == np.round(arr))][:3]}")
        if arr.size and np.max(np.abs(arr)) > 2.0**62:
            raise RodwarpError(f"pinned vertex index {float(np.max(np.abs(arr))):g} is out of range")
    idx = arr.astype(np.int64)
    if n_vertices is not None and idx.size and (idx.min() < 0 or idx.max() >= n_vertices):
        raise RodwarpError(f"pinned vertex index out of range 0..{n_vertices - 1}, got "
                           f"{int(idx.min() if idx.min() < 0 else idx.max())}")
    return idx
