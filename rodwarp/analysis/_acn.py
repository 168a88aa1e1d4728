"""Gauss linking integral and average crossing number (ACN) of polylines, exact per segment pair.

The closed form (``docs/fields.md``, "The average crossing number") lives in
:mod:`rodwarp.kernels.acn`; these host functions allocate, launch and sum.  Every segment pair is evaluated exactly (no quadrature), so a polyline's result is
exact up to float64 round-off.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from rodwarp import _warp
from rodwarp.errors import RodwarpError, RodwarpTypeError
from rodwarp.rodset import MAX_COORDINATE


def _points(name: str, p, min_len: int = 2) -> np.ndarray:
    """``p`` as an (n, 3) float64 array of finite points within :data:`MAX_COORDINATE` (1e12) of
    the origin, n >= ``min_len``: farther ones overflow the integral's cubed distances."""
    try:
        arr = np.asarray(p, dtype=np.float64)
    except (TypeError, ValueError):
        arr = None
    if arr is None or isinstance(p, (str, bytes, dict)):
        raise RodwarpTypeError(f"{name} must be an array of 3D points of shape (n, 3), got {type(p).__name__}")
    if arr.ndim == 1 and arr.size == 3:
        arr = arr[None, :]
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise RodwarpError(f"{name} must be an array of 3D points of shape (n, 3), got shape {arr.shape}")
    if arr.shape[0] < min_len:
        raise RodwarpError(f"{name} needs at least {min_len} points, got {arr.shape[0]}")
    if not np.isfinite(arr).all():
        raise RodwarpError(f"{name} holds NaN or infinite coordinates; remove or repair those points")
    if np.max(np.abs(arr)) > MAX_COORDINATE:
        raise RodwarpError(f"{name} holds a coordinate of {float(np.max(np.abs(arr))):.3g}, beyond {MAX_COORDINATE:g} "
                           f"(any length unit); fix those points or use a larger unit")
    return arr


def gauss_linking(p1, p2, p3, p4, device: str | None = "cpu") -> np.ndarray:
    """Signed Gauss linking integral of segment pairs, exactly.

    Parameters
    ----------
    p1, p2, p3, p4 : array_like, shape (n, 3) or (3,)
        Segment i joins ``p1[i]`` to ``p2[i]``; its partner joins ``p3[i]`` to ``p4[i]``.
        Any length unit (the integral is dimensionless); finite and within 1e12 of the origin.
    device : str
        Warp device (``cpu``, ``cuda``, ``auto``).

    Returns
    -------
    ndarray of float64, shape (n,)
        G in (-1/2, 1/2); the pair's average crossing number is ``abs(G)``.  Coplanar,
        parallel, touching and degenerate pairs give exactly 0.
    """
    arrs = [_points(f"p{k + 1}", p, 1) for k, p in enumerate((p1, p2, p3, p4))]
    n = arrs[0].shape[0]
    if any(a.shape[0] != n for a in arrs):
        raise RodwarpError("p1, p2, p3 and p4 must hold the same number of points")
    dev = _warp.resolve_device(device)
    from rodwarp.kernels import acn as k

    wa = [wp.array(a, dtype=wp.vec3d, device=dev) for a in arrs]
    out = wp.zeros(n, dtype=wp.float64, device=dev)
    wp.launch(k.gauss_linking_pairs, dim=n, inputs=[*wa, out], device=dev)
    return out.numpy()


def _polyline_sums(a, b, closed: bool, device) -> tuple[float, float]:
    if not isinstance(closed, (bool, np.bool_)):
        raise RodwarpTypeError(f"closed must be True or False, got {type(closed).__name__} {closed!r}")
    a = _points("a", a)
    b = _points("b", b)
    na = a.shape[0] if closed else a.shape[0] - 1
    nb = b.shape[0] if closed else b.shape[0] - 1
    if closed and (a.shape[0] < 3 or b.shape[0] < 3):
        raise RodwarpError("a closed polygon needs at least 3 vertices")
    dev = _warp.resolve_device(device)
    from rodwarp.kernels import acn as k

    wa = wp.array(a, dtype=wp.vec3d, device=dev)
    wb = wp.array(b, dtype=wp.vec3d, device=dev)
    s = wp.zeros(na, dtype=wp.float64, device=dev)
    sa = wp.zeros(na, dtype=wp.float64, device=dev)
    wp.launch(k.polyline_linking_rows, dim=na, inputs=[wa, na, wb, nb, s, sa], device=dev)
    # math.fsum: exactly rounded sum, so the result does not depend on row order
    import math

    return math.fsum(s.numpy()), math.fsum(sa.numpy())


def linking_number(a, b, closed: bool = True, device: str | None = "cpu") -> float:
    """Sum of the signed Gauss integral over every segment pair of two polylines.

    For two disjoint closed polygons this is their linking number (an integer); for open
    curves it is the (real-valued) Gauss linking integral.

    Parameters
    ----------
    a, b : array_like, shape (n, 3)
        Vertices, finite and within 1e12 of the origin.  With ``closed=True`` the last vertex
        joins the first (do not repeat it).
    closed : bool
        Treat both curves as closed polygons.
    device : str
        Warp device.
    """
    return _polyline_sums(a, b, closed, device)[0]


def average_crossing_number(a, b, closed: bool = False, device: str | None = "cpu") -> float:
    """Average crossing number of two polylines: the sum of |G| over every segment pair.

    (1 / 4 pi) times the double integral of |(t1 x t2).(r1 - r2)| / |r1 - r2|^3 over the two
    curves (each pair of points once): half the mean, over viewing directions, of the number
    of crossings between the two projected curves (the paper's convention; the unit-segment
    pair (-1,0,0)-(1,0,0), (0,-1,1)-(0,1,1) of ``docs/fields.md`` gives 1/6).  Exact for
    polylines.  Open curves by default.

    Parameters
    ----------
    a, b : array_like, shape (n, 3)
        Vertices, any length unit (the result is dimensionless), finite and within 1e12 of
        the origin.
    closed : bool
        Treat both curves as closed polygons.
    device : str
        Warp device.
    """
    return _polyline_sums(a, b, closed, device)[1]
