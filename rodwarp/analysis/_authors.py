"""The paper authors' field convention (``rodwarp analyze --convention authors``), in NumPy.

The published fields (``all_fields.mat``) were computed by the authors' MATLAB routine
``functions/field/compute_mesoscopic_fields.m`` (repository
``entanglement-transition/entanglement-transition-data-code``).  This module reproduces the
*rules* of that routine, written independently (no code is shared): each function says which
rule it mirrors.  ``docs/fields.md`` tabulates every field under both conventions.

The rules, in the routine's terms ("edge" = one segment of a centreline polyline, "kept edge" =
an edge of the ball):

* grid: centres R, R + h, ... up to (extent - R) along each axis, from the lower corner of the
  analysed domain (the routine: ``R:h:size(zstack) - R`` in voxel coordinates);
* a ball keeps an edge when its *first* vertex lies strictly within R of the centre; kept edges
  are not clipped;
* ``n``: distinct rods with a kept edge;
* ``e``: sum of |G| over *ordered* pairs of kept edges of different rods (the full symmetric
  matrix less the self blocks), i.e. every rod pair twice;
* ``e2``: the same sum over the first n kept edges (n = rods in the ball, edges in rod, then
  vertex order), all pairs i != j (a MATLAB indexing slip: the routine meant one chord per rod);
  a pair of edges sharing a vertex counts 1/2 (what its arcsin formula returns there);
* ``S``: the eigenvalue of largest magnitude of <(3 u u^T - I) / 2> over kept edges, every edge
  weighted 1 (may be negative), 0 in an empty ball;
* ``c``: contact points strictly within R / (K V_ball / V_cyl), V_cyl the whole packing's
  bounding cylinder;
* ``phi``: voxels of the binary CT image inside a digital sphere (:func:`phi_from_image`); a rod
  set has no image, so phi is NaN there.
"""

from __future__ import annotations

import math
from typing import Callable

import numpy as np

__all__ = ["CONVENTIONS", "authors_grid", "kept_edges", "gauss_pairs", "rods_in_ball", "entanglement_e",
           "entanglement_e2", "order_authors", "contact_normalisation", "phi_from_image",
           "authors_field_arrays", "compute_authors_fields"]

#: the field conventions of ``rodwarp analyze``: the paper's text (default) and the authors' routine
CONVENTIONS = ("text", "authors")


def authors_grid(domain, radius: float, spacing: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ball centres along x, y and z under the authors' rule.

    Mirrors ``center_x = R:h:a-R``: from R above the lower corner in steps of h, up to R below
    the upper corner (so every ball lies in the domain; a domain narrower than 2 R has no centre
    on that axis).

    Parameters
    ----------
    domain : array_like (2, 3)
        Lower and upper corner (length).
    radius, spacing : float
        Ball radius R and grid spacing h (length).

    Returns
    -------
    (x, y, z) : tuple of ndarray
        Centre coordinates (length).
    """
    dom = np.asarray(domain, dtype=np.float64)
    out = []
    for k in range(3):
        lo, hi = dom[0, k], dom[1, k]
        span = (hi - radius) - (lo + radius)
        n = int(math.floor(span / spacing + 1e-9)) + 1 if span >= -1e-9 * radius else 0
        out.append(lo + radius + spacing * np.arange(n))
    return out[0], out[1], out[2]


def kept_edges(starts: np.ndarray, centre, radius: float) -> np.ndarray:
    """Edges the authors' ball keeps: first vertex strictly within R of the centre.

    Mirrors ``I_cl = rwnorm(edges(:,1:3) - center) < R`` (no clipping; the end vertex may lie
    outside the ball, and a rod's last vertex is never a first vertex).

    Parameters
    ----------
    starts : ndarray (E, 3)
        First vertex of every edge (length).
    centre : array_like (3,)
        Ball centre (length).
    radius : float
        Ball radius R (length).

    Returns
    -------
    ndarray of bool (E,)
    """
    d = starts - np.asarray(centre, dtype=np.float64)
    return _dot(d, d) < radius * radius


def _dot(a, b):
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _solid_angle(u, v, w):
    """Signed solid angle of the triangle (u, v, w) seen from the origin (Van Oosterom-Strackee)."""
    # component arithmetic, not np.cross / np.linalg.norm: a ball calls this on a few hundred
    # pairs, where those functions' overhead outweighs the arithmetic
    nu, nv, nw = (np.sqrt(_dot(a, a)) for a in (u, v, w))
    vx, vy, vz = v[..., 0], v[..., 1], v[..., 2]
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    num = u[..., 0] * (vy * wz - vz * wy) + u[..., 1] * (vz * wx - vx * wz) + u[..., 2] * (vx * wy - vy * wx)
    den = nu * nv * nw + _dot(u, v) * nw + _dot(u, w) * nv + _dot(v, w) * nu
    return 2.0 * np.arctan2(num, den)


def gauss_pairs(a0, a1, b0, b1) -> np.ndarray:
    """Gauss linking integral G of segment pairs (broadcast), dimensionless.

    G of straight segments a0 -> a1 and b0 -> b1 is the solid angle that the quadrilateral
    (a0 - b0, a1 - b0, a1 - b1, a0 - b1) subtends at the origin, over 4 pi; |G| is their average
    crossing number.  This is the value of the authors' ``compute_lk`` (a four-arcsin form of the
    same solid angle) for every non-degenerate pair; degenerate pairs (parallel, touching,
    coplanar) give 0 here.

    Parameters
    ----------
    a0, a1, b0, b1 : ndarray (..., 3)
        Segment end points (length); broadcast against each other.

    Returns
    -------
    ndarray (...)
    """
    p, q, r, s = a0 - b0, a1 - b0, a1 - b1, a0 - b1
    omega = _solid_angle(p, q, r) + _solid_angle(p, r, s)
    return omega / (4.0 * math.pi)


def rods_in_ball(rod: np.ndarray) -> int:
    """``n`` under the authors' rule: distinct rods among the kept edges.

    Mirrors ``numel(unique(edges(I_cl, 7)))``.

    Parameters
    ----------
    rod : ndarray of int (m,)
        Rod of each kept edge.

    Returns
    -------
    int
        Rods.
    """
    return int(len(np.unique(rod)))


def entanglement_e(a0, a1, rod) -> float:
    """``e`` under the authors' rule: every rod pair counted twice.

    Mirrors ``sum(abs(pdist2(E, E, @compute_lk)))`` over the full m x m matrix of kept edges
    less, for each rod, the sum of its own block: the ordered pairs (i, j) of kept edges of
    different rods, each |G| once per order.  Kept edges are whole (not clipped).

    Parameters
    ----------
    a0, a1 : ndarray (m, 3)
        Kept edges' first and second vertices (length).
    rod : ndarray of int (m,)
        Their rods.

    Returns
    -------
    float
        Dimensionless.
    """
    if len(rod) < 2:
        return 0.0
    # |G| is symmetric in its two edges: each unordered pair of edges of different rods once,
    # counted twice (half the solid angles of the full matrix; the self blocks never computed)
    i, j = np.triu_indices(len(rod), 1)
    other = rod[i] != rod[j]
    i, j = i[other], j[other]
    return 2.0 * float(np.sum(np.abs(gauss_pairs(a0[i], a1[i], a0[j], a1[j]))))


def entanglement_e2(a0, a1, n_rods: int) -> float:
    """``e2`` as the authors' routine computes it.

    The routine means one chord per rod (first kept edge's start to last kept edge's end) but
    indexes the kept edges with a mask over the n distinct rods
    (``edges(labels == labels(i), :)``), which selects kept edge i: its "chords" are the first n
    kept edges in rod, then vertex order, each given a distinct label.  e2 sums |lk| over all
    ordered pairs i != j of them (the self blocks are the diagonal alone).  Where two of them
    share a vertex (consecutive edges of one rod), ``compute_lk``'s normals are 0/0 = NaN,
    MATLAB's ``min``/``max`` clip NaN to 1, and the pair reads |lk| = 2 pi / 4 pi = 1/2 (its sign
    is round-off, non-zero in general): counted 1/2 here.

    Parameters
    ----------
    a0, a1 : ndarray (m, 3)
        Kept edges' vertices (length), in rod, then vertex order.
    n_rods : int
        Rods in the ball (``n``).

    Returns
    -------
    float
        Dimensionless.
    """
    k = min(int(n_rods), len(a0))
    if k < 2:
        return 0.0
    p0, p1 = a0[:k], a1[:k]
    # symmetric in the pair: each unordered pair i < j once, counted twice
    i, j = np.triu_indices(k, 1)
    g = np.abs(gauss_pairs(p0[i], p1[i], p0[j], p1[j]))
    shared = np.zeros(len(i), bool)
    for u in (p0[i], p1[i]):
        for v in (p0[j], p1[j]):
            shared |= np.all(u == v, axis=-1)
    return 2.0 * float(np.sum(np.where(shared, 0.5, g)))


def order_authors(a0, a1) -> float:
    """``S`` under the authors' rule (``compute_orientational_order``).

    Every kept edge weighs 1 whatever its length; Q = (3 <u u^T> - I) / 2 and S is the
    eigenvalue of largest *magnitude* (``max(abs(diag(D)))``), so it is negative (down to -1/2)
    for rods spread in a plane; 0 in an empty ball.

    Parameters
    ----------
    a0, a1 : ndarray (m, 3)
        Kept edges' vertices (length).

    Returns
    -------
    float
        Dimensionless.
    """
    if len(a0) == 0:
        return 0.0
    u = a0 - a1
    u = u / np.linalg.norm(u, axis=1, keepdims=True)
    Q = (3.0 * (u.T @ u) / len(u) - np.eye(3)) / 2.0
    w = np.linalg.eigvalsh(Q)
    return float(w[np.argmax(np.abs(w))])


def contact_normalisation(starts, ends, n_contacts: int, radius: float) -> float:
    """Contacts a ball expects under the authors' rule: K V_ball / V_cyl.

    Mirrors ``expected_number_of_contacts``: the packing's cylinder has height the largest z of
    any edge vertex (measured from z = 0, not from the lowest vertex) and diameter the mean of
    the x and y extents of the vertices; V_cyl = pi D^2 H / 4, V_ball = 4/3 pi R^3.

    Parameters
    ----------
    starts, ends : ndarray (E, 3)
        Every edge's vertices (length).
    n_contacts : int
        Contacts of the whole packing, K.
    radius : float
        Ball radius R (length).

    Returns
    -------
    float
        Contact points (0 when the cylinder has no volume).
    """
    v = np.concatenate([starts, ends])
    height = float(np.max(v[:, 2]))
    diameter = float((np.ptp(v[:, 0]) + np.ptp(v[:, 1])) / 2.0)
    v_cyl = math.pi * diameter**2 * height / 4.0
    v_ball = 4.0 * math.pi / 3.0 * radius**3
    return n_contacts * v_ball / v_cyl if v_cyl > 0 else 0.0


def phi_from_image(image: np.ndarray, centre_index, radius: int) -> float:
    """``phi`` under the authors' rule: occupied voxels in a digital sphere of a binary image.

    Mirrors ``nnz(crop & I_sphere) / nnz(I_sphere)``: the crop is the (2R+1)^3 voxels from
    centre - R to centre + R, and the mask holds the offsets -R+1 .. R+1 with
    x^2 + y^2 + z^2 < R^2, so the digital sphere sits one voxel below the centre on every axis.

    Parameters
    ----------
    image : ndarray of bool, 3-D
        Binary image (rod voxels True), indexed like ``centre_index``.
    centre_index : tuple of 3 int
        Ball centre, voxel indices (0-based), at least R from the lower faces and R from the upper.
    radius : int
        R in voxels.

    Returns
    -------
    float
        Dimensionless.
    """
    R = int(radius)
    off = np.arange(2 * R + 1) - R + 1  # the mask's offsets, (1:2R+1) - R
    mask = (off[:, None, None] ** 2 + off[None, :, None] ** 2 + off[None, None, :] ** 2) < R**2
    c = [int(i) for i in centre_index]
    crop = np.asarray(image, bool)[c[0] - R:c[0] + R + 1, c[1] - R:c[1] + R + 1, c[2] - R:c[2] + R + 1]
    return float(np.count_nonzero(crop & mask)) / float(np.count_nonzero(mask))


def authors_field_arrays(starts, ends, rod, contact_points, x, y, z, radius: float, rod_ends=None,
                         progress: Callable[[int, int], None] | None = None) -> dict:
    """Every field of the authors' routine on a grid of centres (arrays (nz, ny, nx)).

    Parameters
    ----------
    starts, ends : ndarray (E, 3)
        Edges of every rod, in rod, then vertex order (length).
    rod : ndarray of int (E,)
        Rod of each edge.
    contact_points : ndarray (K, 3)
        One point per contact of the packing (length).
    x, y, z : ndarray
        Centre coordinates (:func:`authors_grid`, length).
    radius : float
        Ball radius R (length).
    rod_ends : ndarray (P, 3), optional
        Points counted within R for ``n_ends`` (rodwarp's own field, not the routine's).
    progress : callable(done, total), optional
        Called after each z layer with balls done and balls to do.

    Returns
    -------
    dict
        ``n``, ``e``, ``e2``, ``S``, ``c``, ``contacts``, ``n_ends`` (``phi`` is not here: it
        needs an image, :func:`phi_from_image`) and ``c_normalisation`` (float).
    """
    starts = np.asarray(starts, np.float64)
    ends = np.asarray(ends, np.float64)
    rod = np.asarray(rod)
    pts = np.asarray(contact_points, np.float64).reshape(-1, 3)
    ends_pts = np.zeros((0, 3)) if rod_ends is None else np.asarray(rod_ends, np.float64).reshape(-1, 3)
    shape = (len(z), len(y), len(x))
    out = {k: np.zeros(shape) for k in ("n", "e", "e2", "S", "c", "contacts", "n_ends")}
    norm = contact_normalisation(starts, ends, len(pts), radius) if len(starts) else 0.0
    total = int(np.prod(shape))
    done = 0
    for iz, cz in enumerate(z):
        # the routine's slab: edges and contacts within 1.1 R in z (a prefilter, same result)
        slab = np.abs(starts[:, 2] - cz) < 1.1 * radius
        z0, z1, zr = starts[slab], ends[slab], rod[slab]
        zpts = pts[np.abs(pts[:, 2] - cz) < 1.1 * radius]
        for iy, cy in enumerate(y):
            # and the row's: edges and contacts within 1.1 R in y too (a prefilter, same result)
            row = np.abs(z0[:, 1] - cy) < 1.1 * radius
            s0, s1, sr = z0[row], z1[row], zr[row]
            rpts = zpts[np.abs(zpts[:, 1] - cy) < 1.1 * radius]
            for ix, cx in enumerate(x):
                c = np.array([cx, cy, cz])
                keep = kept_edges(s0, c, radius)
                a0, a1, r = s0[keep], s1[keep], sr[keep]
                n = rods_in_ball(r)
                dk = rpts - c
                k = np.count_nonzero(_dot(dk, dk) < radius * radius) if len(rpts) else 0
                out["n"][iz, iy, ix] = n
                out["e"][iz, iy, ix] = entanglement_e(a0, a1, r)
                out["e2"][iz, iy, ix] = entanglement_e2(a0, a1, n)
                out["S"][iz, iy, ix] = order_authors(a0, a1)
                out["contacts"][iz, iy, ix] = k
                out["c"][iz, iy, ix] = k / norm if norm > 0 else 0.0
                out["n_ends"][iz, iy, ix] = (np.count_nonzero(np.linalg.norm(ends_pts - c, axis=1) < radius)
                                             if len(ends_pts) else 0)
        done += len(x) * len(y)
        if progress is not None:
            progress(done, total)
    out["c_normalisation"] = norm
    return out


def compute_authors_fields(rods, params, contacts, source: str, progress=None):
    """The fields of a rod set under the authors' convention, as :class:`Fields`.

    Parameters
    ----------
    rods : RodSet
        The rods (lengths in ``rods.units``).
    params : FieldParams
        Resolved radius, spacing and domain (:func:`rodwarp.analysis._fields.resolve_params`).
    contacts : Contacts
        The packing's contacts (their points are counted).
    source : str
        Where the contacts came from.
    progress : callable(done, total), optional

    Returns
    -------
    Fields
        ``n``, ``e``, ``S``, ``c``, ``contacts``, ``n_ends`` by the authors' rules; ``phi`` NaN
        (the routine measures it on the CT image, which a rod set does not have).  ``e2`` has no
        row in the field registry: it is kept out of ``Fields`` (:func:`authors_field_arrays`
        returns it).
    """
    import time

    from rodwarp.analysis._fieldset import Fields

    t0 = time.perf_counter()
    x, y, z = authors_grid(params.domain, params.radius, params.spacing)
    starts, ends, rod = rods.segments()
    o = rods.offsets
    rod_ends = np.concatenate([rods.points[o[:-1]], rods.points[o[1:] - 1]])
    arr = authors_field_arrays(starts, ends, rod, np.asarray(contacts.point, np.float64), x, y, z,
                               params.radius, rod_ends=rod_ends, progress=progress)
    norm = arr.pop("c_normalisation")
    arr.pop("e2")
    arr["phi"] = np.full(arr["e"].shape, np.nan)
    attrs = {
        "convention": "authors", "diameter": params.diameter, "length": params.length,
        "domain": params.domain.tolist(), "keep_outside": params.keep_outside,
        "c_normalisation": norm, "Z": 2.0 * len(contacts) / rods.n_rods,
        "n_rods": rods.n_rods, "n_segments": int(len(rod)), "n_contacts": len(contacts),
        "contact_source": source, "contact_tolerance": params.contact_tolerance,
        "n_voxels_computed": int(arr["e"].size), "device": "numpy",
        "wall_s": time.perf_counter() - t0,
    }
    return Fields(**arr, x=x, y=y, z=z, radius=params.radius, spacing=params.spacing, units=rods.units,
                  attrs=attrs)
