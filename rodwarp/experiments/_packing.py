"""Random packings of straight rods by random sequential addition (RSA).

Candidates (uniform centre, isotropic direction) are drawn in batches; a Warp kernel finds,
through a hash grid over the segments of the rods already placed, whether each candidate
comes closer than one diameter (surface gap < 0) to any of them; the host then accepts
candidates in order, checking each against the candidates accepted earlier in the same batch.
A placement that runs long (tens of thousands of rods take tens of seconds) says so on stderr
within :data:`rodwarp._util.NOTE_AFTER_S` and shows a bar over the rods placed.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from rodwarp import _warp
from rodwarp._util import slow_phase
from rodwarp.errors import RodwarpError
from rodwarp.kernels.packing import candidate_clearance
from rodwarp.rodset import RodSet


def isotropic_directions(rng: np.random.Generator, n: int) -> np.ndarray:
    """``n`` unit vectors uniform on the sphere."""
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def random_packing(
    n_rods: int,
    length: float,
    diameter: float,
    box,
    *,
    n_vertices: int = 10,
    seed: int = 0,
    clearance: float = 0.0,
    cylinder: float | None = None,
    max_attempts: int | None = None,
    device: str = "cpu",
    batch: int = 4096,
    progress: bool | None = None,
) -> RodSet:
    """Place ``n_rods`` non-overlapping straight rods fully inside a box.

    Parameters
    ----------
    n_rods : int
        Number of rods N.
    length, diameter : float
        Rod length l and diameter d (m).
    box : (3,) float
        Box size (m); the box spans [0, X] x [0, Y] x [0, Z].
    n_vertices : int
        Vertices per rod (evenly spaced).
    seed : int
        Seed of the random generator; the same seed gives the same packing.
    clearance : float
        Extra surface gap required between rods (m); 0 means touching is allowed.
    cylinder : float, optional
        Also keep every rod inside the vertical cylinder of this radius (m) about the box's
        axis (through the centre of its x-y face): a pour into a round container.
    max_attempts : int, optional
        Give up after this many candidates, inside the box or not (default 20000 N + 1e5).
    device : str
        Warp device for the clearance kernel.
    batch : int
        Candidates drawn and tested at a time.
    progress : bool, optional
        Once the placement has run :data:`rodwarp._util.NOTE_AFTER_S`, print a note and a bar
        over the rods placed on stderr; None: unless the process is quiet
        (:func:`rodwarp._util.quiet`: a library call is, a command is unless ``--quiet``). A
        quick placement prints nothing.

    Returns
    -------
    RodSet
        The packing, with ``box`` and ``attrs['seed']`` recorded.

    Raises
    ------
    RodwarpError
        Rods longer than the box allows, or N rods could not be placed.
    """
    _warp.init()
    box = np.asarray(box, dtype=np.float64)
    if n_rods < 1:
        raise RodwarpError(f"number of rods must be >= 1, got {n_rods}")
    if length + diameter > box.min() * math.sqrt(3) or np.any(box <= diameter):
        raise RodwarpError(f"rods of length {length:g} m cannot fit in a box of {box.tolist()} m")
    rng = np.random.default_rng(seed)
    r = 0.5 * diameter
    h = length / (n_vertices - 1)
    max_attempts = max_attempts or 20000 * n_rods + 100000
    dev = _warp.resolve_device(device)
    grid = wp.HashGrid(64, 64, 64, device=dev)
    reach = h + diameter + clearance
    with slow_phase(f"placing {n_rods} rods", n_rods, enabled=progress, unit="rods") as placed:
        centers, dirs, attempts = _place(rng, n_rods, length, diameter, box, n_vertices=n_vertices,
                                         clearance=clearance, cylinder=cylinder, max_attempts=max_attempts,
                                         batch=batch, grid=grid, reach=reach, dev=dev, placed=placed)
    rods = RodSet.from_straight(centers, dirs, length, r, n_vertices=n_vertices)
    rods.box = np.stack([np.zeros(3), box])
    rods.attrs.update({"generator": "random_sequential_addition", "seed": int(seed), "attempts": int(attempts)})
    return rods


def _place(rng, n_rods, length, diameter, box, *, n_vertices, clearance, cylinder, max_attempts, batch, grid,
           reach, dev, placed):
    """The random sequential addition of :func:`random_packing`: rod centres (N, 3) and unit
    directions (N, 3) (m), and the candidates drawn; ``placed(n)`` is told the rods placed
    before each batch."""
    r = 0.5 * diameter
    placed_a = np.zeros((0, 3))  # segment starts of placed rods
    placed_b = np.zeros((0, 3))
    centers, dirs = [], []
    attempts = 0
    while len(centers) < n_rods:
        placed(len(centers))
        if attempts >= max_attempts:
            raise RodwarpError(
                f"placed only {len(centers)} of {n_rods} rods after {attempts} attempts; "
                f"lower --n-rods or enlarge --box")
        m = min(batch, max_attempts - attempts)
        attempts += m
        d = isotropic_directions(rng, m)
        c = rng.random((m, 3)) * box
        half = 0.5 * length * np.abs(d) + r  # half extent of each rod along each axis
        # uniform position and isotropic direction, rejected unless fully inside: in a box
        # narrower than ~l this favours steep rods, as in the paper's procedure (docs/protocol.md)
        ok = np.all((c - half >= 0.0) & (c + half <= box), axis=1)
        if cylinder is not None:
            # a segment lies in the (convex) cylinder when both its ends do
            axis = 0.5 * box[:2]
            for sign in (-0.5, 0.5):
                ok &= np.hypot(*(c[:, :2] + sign * length * d[:, :2] - axis).T) <= cylinder - r
        d, c = d[ok], c[ok]
        if len(c) == 0:
            continue
        cand_a, cand_b = _segments(c, d, length, n_vertices)
        if len(placed_a):
            gap = _min_gap_to_placed(grid, placed_a, placed_b, cand_a, cand_b, n_vertices - 1, reach, diameter, dev)
        else:
            gap = np.full(len(c), np.inf)
        for k in np.flatnonzero(gap >= clearance):
            if len(centers) >= n_rods:
                break
            if centers:
                # candidates accepted earlier in this batch are not in the grid yet
                new = len(centers) - len(placed_a) // (n_vertices - 1)
                if new > 0 and not _clear_of(c[k], d[k], centers[-new:], dirs[-new:], length, diameter + clearance):
                    continue
            centers.append(c[k])
            dirs.append(d[k])
        pa, pb = _segments(np.array(centers), np.array(dirs), length, n_vertices)
        placed_a, placed_b = pa, pb
    placed(len(centers))
    return np.array(centers), np.array(dirs), attempts


def _segments(c, d, length, n_vertices):
    s = np.linspace(-0.5, 0.5, n_vertices) * length
    pts = c[:, None, :] + s[None, :, None] * d[:, None, :]
    return pts[:, :-1].reshape(-1, 3), pts[:, 1:].reshape(-1, 3)


def _min_gap_to_placed(grid, pa, pb, ca, cb, segs_per_rod, reach, diameter, dev):
    mids = wp.array(((pa + pb) * 0.5).astype(np.float32), dtype=wp.vec3, device=dev)
    grid.build(mids, float(reach))
    out = wp.zeros(len(ca), dtype=wp.float64, device=dev)
    wp.launch(candidate_clearance, dim=len(ca), device=dev, inputs=[
        grid.id, wp.array(pa, dtype=wp.vec3d, device=dev), wp.array(pb, dtype=wp.vec3d, device=dev),
        wp.array(ca, dtype=wp.vec3d, device=dev), wp.array(cb, dtype=wp.vec3d, device=dev),
        float(reach), wp.float64(diameter), out])
    return out.numpy().reshape(-1, segs_per_rod).min(axis=1)


def _clear_of(c, d, centers, dirs, length, min_dist):
    from rodwarp.rodset import segment_distance

    p0 = c - 0.5 * length * d
    p1 = c + 0.5 * length * d
    C = np.asarray(centers)
    D = np.asarray(dirs)
    q0 = C - 0.5 * length * D
    q1 = C + 0.5 * length * D
    return bool(np.all(segment_distance(p0, p1, q0, q1) >= min_dist))


def orientation_statistics(rods: RodSet) -> dict:
    """Orientation order of a rod set: nematic S, <|u_z|> and <u_z^2> (isotropic: 0, 0.5, 1/3)."""
    ends = rods.points[rods.offsets[1:] - 1] - rods.points[rods.offsets[:-1]]
    u = ends / np.linalg.norm(ends, axis=1, keepdims=True)
    Q = 1.5 * (u[:, :, None] * u[:, None, :]).mean(axis=0) - 0.5 * np.eye(3)
    return {
        "nematic_S": float(np.linalg.eigvalsh(Q)[-1]),
        "mean_abs_uz": float(np.abs(u[:, 2]).mean()),
        "mean_uz2": float((u[:, 2] ** 2).mean()),
    }
