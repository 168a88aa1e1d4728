"""A second CT phantom generator, written apart from ``rodwarp phantom`` so that segmentation is
scored on data it was not tuned on (issue 50).

Nothing here comes from :mod:`rodwarp.ct`; every step takes another path:

- **Placement.** Scenes of the paper's regime, in voxel units: thin rods, mostly within 25
  degrees of horizontal, lying in bundles of 2-5 parallel rods that touch with zero gap, with
  crossing rods laid on them (:func:`touching_bundles`). Also wire tangles, smooth closed-form
  curves as chains of short capsules (:func:`wire_tangle`), kept apart or (``touching=True``)
  moved rigidly onto the wires they cross until they touch at zero gap. Each scene states its
  true contacts from the way it was built: touching pairs at gap 0, every other pair at least a
  voxel apart.
- **Partial volume.** Each voxel's filled fraction is the exact volume of the unit cube on the
  inner side of the plane tangent to the nearest surface (:func:`cube_fraction`, a closed form),
  with that plane moved by the surface's mean bend over the voxel. This is exact for a flat
  surface; a capsule's total comes within 1% of its volume at radius 1.5 voxels. The ``rodwarp
  phantom`` renderer supersamples instead.
- **Blur.** A point-spread function with a Gaussian core and an exponential tail, the shape
  micro-CT edge spread functions show (the tail is the scatter). It is applied by FFT
  convolution, not a separable Gaussian filter.
- **Noise.** Photon counts: Poisson with a mean of ``counts`` times the local grey value, so the
  noise grows with the signal (Gaussian noise at a fixed CNR does not).
- **Artefacts.** Beam hardening darkens the inside of dense regions (an attenuation that grows
  with the material's large-scale density). Rings are concentric about the z axis, with random
  amplitudes per radius.

Volumes are indexed ``(z, y, x)``; points are ``(x, y, z)`` in voxels, the centre of voxel
``(0, 0, 0)`` at the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = ["GeneratedScene", "cube_fraction", "capsule_distance", "render", "touching_bundles", "wire_tangle",
           "psf_kernel", "capsule_volume", "polyline_distance"]


@dataclass
class GeneratedScene:
    """A scene of capsules in voxel units with its truth.

    Attributes
    ----------
    shape : (3,) int
        Volume shape (z, y, x).
    p0, p1 : (N, 3) float
        Capsule axis end points (x, y, z), voxels.
    radius : (N,) float
        Capsule radii (voxels).
    rod : (N,) int
        The true rod (or filament) each capsule belongs to: a straight rod is one capsule, a
        wire a chain of them.
    contacts : list of (int, int)
        True touching rod pairs (rod indices, i < j).
    polylines : list of (M, 3) arrays
        Each rod's centreline, voxels.
    meta : dict
        The generator's parameters and seed.
    """

    shape: tuple
    p0: np.ndarray
    p1: np.ndarray
    radius: np.ndarray
    rod: np.ndarray
    contacts: list
    polylines: list
    meta: dict = field(default_factory=dict)

    @property
    def n_rods(self) -> int:
        return len(self.polylines)


def capsule_volume(radius: float, length: float) -> float:
    """Volume of a capsule: pi r^2 L + 4/3 pi r^3 (voxels^3)."""
    return math.pi * radius * radius * length + 4.0 / 3.0 * math.pi * radius ** 3


# --------------------------------------------------------------------------- partial volume


def cube_fraction(d, n) -> np.ndarray:
    """Volume of the unit cube centred at the origin on the side ``n . x <= d`` of a plane.

    The closed form is the cube cut by a plane: with the normal's absolute components ``a`` and
    ``s = (|n_x| + |n_y| + |n_z|) / 2``, the volume below ``n . x = t`` is a sum of clipped cubes,
    ``sum_k (-1)^k C(k) max(0, t + s - corner_k)^3 / (6 a_x a_y a_z)``. Degenerate normals with a
    zero component take the 2-D or 1-D form instead.

    Parameters
    ----------
    d : array_like
        Signed offset of the plane from the cube's centre along the unit normal (voxels);
        positive means the centre is inside.
    n : (..., 3) array_like
        Unit normals.

    Returns
    -------
    ndarray
        The filled fraction in [0, 1].
    """
    d = np.asarray(d, float)
    a = np.sort(np.abs(np.asarray(n, float)), axis=-1)[..., ::-1]  # a0 >= a1 >= a2 >= 0
    a = np.broadcast_to(a, d.shape + (3,))
    t = d + 0.5 * a.sum(axis=-1)  # distance from the lowest corner
    out = np.empty_like(d)
    eps = 1e-9
    full = a[..., 2] > eps
    plane = (~full) & (a[..., 1] > eps)
    line = ~(full | plane)
    if full.any():
        aa, tt = a[full], t[full]
        v = np.zeros_like(tt)
        # inclusion-exclusion over the 8 corners of the box [0, a0] x [0, a1] x [0, a2]
        for sx in (0, 1):
            for sy in (0, 1):
                for sz in (0, 1):
                    c = sx * aa[:, 0] + sy * aa[:, 1] + sz * aa[:, 2]
                    v += (-1) ** (sx + sy + sz) * np.maximum(tt - c, 0.0) ** 3
        out[full] = v / (6.0 * aa[:, 0] * aa[:, 1] * aa[:, 2])
    if plane.any():
        aa, tt = a[plane], t[plane]
        v = np.zeros_like(tt)
        for sx in (0, 1):
            for sy in (0, 1):
                c = sx * aa[:, 0] + sy * aa[:, 1]
                v += (-1) ** (sx + sy) * np.maximum(tt - c, 0.0) ** 2
        out[plane] = v / (2.0 * aa[:, 0] * aa[:, 1])
    if line.any():
        out[line] = t[line] / a[line][:, 0]
    return np.clip(out, 0.0, 1.0)


def capsule_distance(pts: np.ndarray, p0, p1, r: float):
    """Signed distance of points (..., 3) to a capsule's surface (negative inside), the outward
    unit normal there (any unit vector on the axis), and how many directions the surface curves
    in there (1 on the cylinder, 2 on the end caps)."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    ab = p1 - p0
    L2 = float(ab @ ab)
    t = np.clip(((pts - p0) @ ab) / L2, 0.0, 1.0) if L2 > 0 else np.zeros(pts.shape[:-1])
    rel = pts - (p0 + t[..., None] * ab)
    dist = np.linalg.norm(rel, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        normal = np.where(dist[..., None] > 1e-12, rel / dist[..., None], np.array([0.0, 0.0, 1.0]))
    curved = np.where((t <= 0.0) | (t >= 1.0), 2, 1)
    return dist - r, normal, curved


def occupancy(scene: GeneratedScene) -> np.ndarray:
    """Each voxel's filled fraction: :func:`cube_fraction` of the plane tangent to the nearest
    capsule surface (the capsule of smallest signed distance: the union of capsules), moved
    inwards by the surface's mean bend over the voxel, 1/(24 r) per curved direction."""
    shape = tuple(int(s) for s in scene.shape)
    best = np.full(shape, np.inf)
    occ = np.zeros(shape)
    for p0, p1, r in zip(scene.p0, scene.p1, scene.radius):
        lo = np.floor(np.minimum(p0, p1) - r - 1).astype(int)
        hi = np.ceil(np.maximum(p0, p1) + r + 1).astype(int)
        lo = np.maximum(lo, 0)
        hi = np.minimum(hi, np.array(shape[::-1]) - 1)
        if np.any(hi < lo):
            continue
        zs, ys, xs = (np.arange(lo[k], hi[k] + 1) for k in (2, 1, 0))
        Z, Y, X = np.meshgrid(zs, ys, xs, indexing="ij")
        pts = np.stack([X, Y, Z], axis=-1).astype(float)
        d, n, curved = capsule_distance(pts, p0, p1, float(r))
        sl = (slice(lo[2], hi[2] + 1), slice(lo[1], hi[1] + 1), slice(lo[0], hi[0] + 1))
        nearer = d < best[sl]
        if not nearer.any():
            continue
        # the surface bends away from its tangent plane by q^2 / (2 r) at an in-plane offset q;
        # over a voxel (mean q^2 = 1/12 per curved direction) the plane moves inwards by that
        frac = cube_fraction(-d - curved / (24.0 * float(r)), n)
        block_best, block_occ = best[sl], occ[sl]
        block_best[nearer] = d[nearer]
        # a voxel inside two touching capsules is full; else the nearest surface decides
        block_occ[nearer] = np.maximum(frac[nearer], block_occ[nearer] * (d[nearer] < 0))
    return occ


# --------------------------------------------------------------------------- image model


def psf_kernel(sigma: float = 0.8, tail: float = 0.08, tail_length: float = 2.5, size: int | None = None):
    """A 3-D point-spread function: ``(1 - tail)`` Gaussian core of ``sigma`` voxels plus ``tail``
    of an exponential ``exp(-r / tail_length)``; normalised to sum 1."""
    size = size or int(2 * math.ceil(max(3 * sigma, 4 * tail_length)) + 1)
    h = size // 2
    z, y, x = np.mgrid[-h:h + 1, -h:h + 1, -h:h + 1].astype(float)
    r = np.sqrt(x * x + y * y + z * z)
    core = np.exp(-0.5 * (r / max(sigma, 1e-6)) ** 2)
    core /= core.sum()
    expo = np.exp(-r / tail_length)
    expo /= expo.sum()
    k = (1.0 - tail) * core + tail * expo
    return k / k.sum()


def render(scene: GeneratedScene, *, background: float = 0.2, foreground: float = 0.8, counts: float = 400.0,
           psf_sigma: float = 0.8, psf_tail: float = 0.08, hardening: float = 0.15, rings: float = 0.02,
           seed: int = 0) -> np.ndarray:
    """The scene as a 16-bit CT volume (z, y, x).

    Parameters
    ----------
    background, foreground : float
        Grey values (fractions of full scale) of air and rod material before artefacts.
    counts : float
        Photon counts per unit grey value: the noise is Poisson, its variance the grey value
        over ``counts``; at the defaults the contrast-to-noise ratio in the material is about
        0.6 / sqrt(0.8 / 400) = 13.
    psf_sigma, psf_tail : float
        The point-spread function (:func:`psf_kernel`).
    hardening : float
        Beam hardening: the grey value is lowered by this fraction of the material's density
        smoothed over 12 voxels (dense cores of a pile read darker).
    rings : float
        Amplitude of the ring artefacts (fraction of full scale, random per unit radius).
    seed : int
        Seed of the noise and the rings.
    """
    from scipy import ndimage, signal

    rng = np.random.default_rng(seed)
    occ = occupancy(scene)
    img = background + (foreground - background) * occ
    if hardening > 0:
        dense = ndimage.uniform_filter(occ, size=12, mode="nearest")
        img = img - hardening * (foreground - background) * dense * occ
    img = signal.fftconvolve(img, psf_kernel(psf_sigma, psf_tail), mode="same")
    if rings > 0:
        nz, ny, nx = img.shape
        y, x = np.mgrid[0:ny, 0:nx]
        rad = np.hypot(x - (nx - 1) / 2, y - (ny - 1) / 2)
        amp = rings * rng.standard_normal(int(rad.max()) + 2)
        img = img + amp[rad.astype(int)][None, :, :]
    lam = np.clip(img, 0.0, None) * counts
    img = rng.poisson(lam) / counts
    return np.clip(np.round(img * 65535.0), 0, 65535).astype(np.uint16)


# --------------------------------------------------------------------------- scenes


def _segment_distance(p0, p1, q0, q1) -> float:
    """Closest distance between segments p0p1 and q0q1: the minimiser of the quadratic
    |p0 + a u - q0 - b v|^2 over the unit square, found on its interior critical point or on its
    four edges (each edge a clamped 1-D projection)."""
    u, v, w = p1 - p0, q1 - q0, p0 - q0
    A, B, C, D, E = u @ u, u @ v, v @ v, u @ w, v @ w
    cands = []
    den = A * C - B * B
    if den > 1e-12 * max(A * C, 1e-30):
        a = (B * E - C * D) / den
        b = (A * E - B * D) / den
        if 0.0 <= a <= 1.0 and 0.0 <= b <= 1.0:
            cands.append((a, b))
    for a in (0.0, 1.0):  # edges a fixed: b by projection
        cands.append((a, float(np.clip((E + a * B) / C, 0.0, 1.0)) if C > 0 else 0.0))
    for b in (0.0, 1.0):  # edges b fixed: a by projection
        cands.append((float(np.clip((b * B - D) / A, 0.0, 1.0)) if A > 0 else 0.0, b))
    return float(min(np.linalg.norm(w + a * u - b * v) for a, b in cands))


def _direction(rng, max_tilt_deg: float) -> np.ndarray:
    """A random direction within ``max_tilt_deg`` of horizontal (uniform azimuth, tilt uniform
    in sin)."""
    phi = rng.uniform(0.0, 2.0 * math.pi)
    s = rng.uniform(-math.sin(math.radians(max_tilt_deg)), math.sin(math.radians(max_tilt_deg)))
    c = math.sqrt(1.0 - s * s)
    return np.array([c * math.cos(phi), c * math.sin(phi), s])


def touching_bundles(shape=(96, 128, 128), radius: float = 2.0, n_bundles: int = 6, bundle_size=(2, 5),
                     n_crossing: int = 6, length: float = 70.0, max_tilt_deg: float = 25.0, seed: int = 0,
                     max_tries: int = 4000) -> GeneratedScene:
    """Bundles of parallel rods touching with zero gap, and crossing rods laid on them.

    A bundle is 2-5 rods side by side: a direction within ``max_tilt_deg`` of horizontal, the
    rods' axes ``2 radius`` apart along a horizontal perpendicular (they touch along their whole
    length). A crossing rod lies across a bundle, its axis ``2 radius`` from the bundle's plane
    (point contacts with every rod of the bundle it crosses). Nothing else touches or overlaps:
    every other pair is kept at least one voxel apart. The true contacts are the bundle
    neighbours and each crossing rod with the rods it lies on.
    """
    rng = np.random.default_rng(seed)
    nz, ny, nx = shape
    hi = np.array([nx - 1, ny - 1, nz - 1], float)
    margin = radius + 2.0
    rods: list[tuple[np.ndarray, np.ndarray]] = []
    contacts: list[tuple[int, int]] = []

    def clear(p0, p1, exempt=()):
        for k, (q0, q1) in enumerate(rods):
            if k in exempt:
                continue
            if _segment_distance(p0, p1, q0, q1) < 2 * radius + 1.0:
                return False
        return True

    def inside(p0, p1):
        return bool(np.all(np.minimum(p0, p1) >= margin) and np.all(np.maximum(p0, p1) <= hi - margin))

    tries = 0
    made = 0
    while made < n_bundles and tries < max_tries:
        tries += 1
        k = int(rng.integers(bundle_size[0], bundle_size[1] + 1))
        u = _direction(rng, max_tilt_deg)
        side = np.cross(u, [0.0, 0.0, 1.0])
        side /= np.linalg.norm(side)
        c = rng.uniform(margin + length / 2 * np.abs(u), hi - margin - length / 2 * np.abs(u))
        axes = [(c + (j - (k - 1) / 2) * 2 * radius * side - length / 2 * u,
                 c + (j - (k - 1) / 2) * 2 * radius * side + length / 2 * u) for j in range(k)]
        if not all(inside(a, b) and clear(a, b) for a, b in axes):
            continue
        first = len(rods)
        rods.extend(axes)
        contacts.extend((first + j, first + j + 1) for j in range(k - 1))
        made += 1
    crossed = 0
    while crossed < n_crossing and tries < 2 * max_tries and rods:
        tries += 1
        base = int(rng.integers(0, len(rods)))
        b0, b1 = rods[base]
        ub = (b1 - b0) / np.linalg.norm(b1 - b0)
        at = b0 + rng.uniform(0.25, 0.75) * (b1 - b0)
        # across the base rod, within the tilt limit, resting on top of it
        ang = rng.uniform(math.radians(40), math.radians(140))
        horiz = np.cross(ub, [0.0, 0.0, 1.0])
        horiz /= np.linalg.norm(horiz)
        u = math.cos(ang) * ub + math.sin(ang) * horiz
        u /= np.linalg.norm(u)
        up = np.cross(ub, u)
        up /= np.linalg.norm(up)
        if up[2] < 0:
            up = -up
        centre = at + 2 * radius * up
        p0, p1 = centre - length / 2 * u, centre + length / 2 * u
        if not inside(p0, p1):
            continue
        # lying on a raft of parallel touching rods it touches every rod of the raft it crosses
        # (all at exactly 2 r); any other rod must stay a voxel clear, with no near misses
        dist = np.array([_segment_distance(p0, p1, q0, q1) for q0, q1 in rods])
        touching = np.flatnonzero(np.abs(dist - 2 * radius) < 1e-6)
        if base not in touching or np.any((dist < 2 * radius + 1.0) & (np.abs(dist - 2 * radius) >= 1e-6)):
            continue
        rods.append((p0, p1))
        contacts.extend((int(k), len(rods) - 1) for k in touching)
        crossed += 1
    p0 = np.array([a for a, _ in rods]).reshape(-1, 3)
    p1 = np.array([b for _, b in rods]).reshape(-1, 3)
    return GeneratedScene(tuple(shape), p0, p1, np.full(len(rods), float(radius)), np.arange(len(rods)),
                          sorted(tuple(sorted(c)) for c in contacts), [np.stack([a, b]) for a, b in rods],
                          {"generator": "touching_bundles", "radius": radius, "n_bundles": made,
                           "n_crossing": crossed, "length": length, "max_tilt_deg": max_tilt_deg, "seed": seed})


def _closest_segments(P0, P1, Q0, Q1):
    """Closest points of every segment pair ``P0[i]P1[i]`` / ``Q0[j]Q1[j]`` (all of positive
    length): the distances (n, m) and, for the closest pair overall, the two points. Per pair
    the line parameter ``s`` on P is clamped to [0, 1], ``t`` on Q follows by projection and is
    clamped, and ``s`` is projected again when ``t`` was clamped (the clamped-lines construction
    of the segment-segment distance)."""
    d1 = (P1 - P0)[:, None, :]
    d2 = (Q1 - Q0)[None, :, :]
    w = P0[:, None, :] - Q0[None, :, :]
    a = np.sum(d1 * d1, axis=-1)
    e = np.sum(d2 * d2, axis=-1)
    b = np.sum(d1 * d2, axis=-1)
    c = np.sum(d1 * w, axis=-1)
    f = np.sum(d2 * w, axis=-1)
    den = a * e - b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        s = np.where(den > 1e-12 * a * e, np.clip((b * f - c * e) / den, 0.0, 1.0), 0.0)
        t = (b * s + f) / e
        lo, hi = t < 0.0, t > 1.0
        t = np.clip(t, 0.0, 1.0)
        s = np.where(lo, np.clip(-c / a, 0.0, 1.0), np.where(hi, np.clip((b - c) / a, 0.0, 1.0), s))
    cp = P0[:, None, :] + s[..., None] * d1
    cq = Q0[None, :, :] + t[..., None] * d2
    D = np.linalg.norm(cp - cq, axis=-1)
    k = np.unravel_index(int(np.argmin(D)), D.shape)
    return D, cp[k], cq[k]


def polyline_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Smallest distance between two polylines (n, 3) and (m, 3): between their segments."""
    D, _, _ = _closest_segments(a[:-1], a[1:], b[:-1], b[1:])
    return float(D.min())


def _wire_curve(rng, hi, margin, length, segments):
    """A closed-form smooth curve: a chord within 35 degrees of horizontal, plus three random
    sinusoids per axis (half as strong in z), as ``segments + 1`` points."""
    u = _direction(rng, 35.0)
    s = np.linspace(-0.5, 0.5, segments + 1)
    c = rng.uniform(margin + 0.3 * length * np.abs(u), hi - margin - 0.3 * length * np.abs(u))
    pts = c + np.outer(s * 0.6 * length, u)
    for axis in range(3):
        for _ in range(3):
            amp = rng.uniform(2.0, 8.0) * (0.5 if axis == 2 else 1.0)
            pts[:, axis] += amp * np.sin(2 * math.pi * rng.uniform(0.3, 1.5) * s + rng.uniform(0, 2 * math.pi))
    return pts


def _self_clear(pts, radius) -> bool:
    """No self-contact: points further apart along the wire than ``4 r + 2`` stay ``2 r + 1``
    apart in space."""
    D = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=-1)
    arc = np.cumsum(np.r_[0.0, np.linalg.norm(np.diff(pts, axis=0), axis=1)])
    far = np.abs(arc[:, None] - arc[None, :]) > 4 * radius + 2
    return not np.any(D[far] < 2 * radius + 1.0)


def _touch_by_translation(pts, targets, lines, gap_to, iters: int = 30, tol: float = 1e-9):
    """Translate the polyline ``pts`` rigidly so that its distance to each polyline
    ``lines[k]`` (k in ``targets``) is exactly ``gap_to``: Newton steps on the translation,
    each the least-norm solution of ``n_k . dt = gap_to - d_k`` (``n_k`` the unit vector
    between the closest points, along which ``d_k`` grows). None when it does not converge."""
    shift = np.zeros(3)
    for _ in range(iters):
        rows, rhs = [], []
        for k in targets:
            q = lines[k]
            D, cp, cq = _closest_segments(pts[:-1] + shift, pts[1:] + shift, q[:-1], q[1:])
            d = float(D.min())
            if d < 1e-9:
                return None
            rows.append((cp - cq) / d)
            rhs.append(gap_to - d)
        if max(abs(v) for v in rhs) < tol:
            return pts + shift
        A = np.array(rows)
        if len(rows) > 1 and np.linalg.svd(A, compute_uv=False)[-1] < 0.2:
            return None  # the contact normals are nearly parallel: the two contacts fight
        shift = shift + np.linalg.lstsq(A, np.array(rhs), rcond=None)[0]
        if np.linalg.norm(shift) > 40.0:
            return None
    return None


def wire_tangle(shape=(96, 128, 128), radius: float = 2.0, n_wires: int = 8, segments: int = 40,
                length: float = 160.0, seed: int = 0, max_tries: int = 400, touching: bool = False,
                touch_probability: float = 0.85, second_touch: float = 0.5) -> GeneratedScene:
    """Curved wires: each a closed-form smooth curve (a sum of three random sinusoids per axis
    about a random chord), cut into ``segments`` capsules. A wire's own turns never touch.

    With ``touching=False`` wires are kept at least one voxel apart from each other (no
    contacts). With ``touching=True`` they touch where they cross, as in a real tangle: each new
    wire, with probability ``touch_probability``, is drawn as above and then moved rigidly
    (Newton steps on its translation, :func:`_touch_by_translation`) until the distance between
    its centreline and a random wire already placed is exactly ``2 radius`` (gap 0 to 1e-9
    voxels), the two crossing at more than 17 degrees; with probability ``second_touch`` it is
    moved to touch the nearest other wire as well (two conditions on the translation). Every
    other pair stays at least a voxel apart, so the true contacts (``scene.contacts``) are
    exactly the pairs made to touch. Wires that cannot be placed that way are drawn again.
    """
    rng = np.random.default_rng(seed)
    nz, ny, nx = shape
    hi = np.array([nx - 1, ny - 1, nz - 1], float)
    margin = radius + 2.0
    lines: list[np.ndarray] = []
    contacts: list[tuple[int, int]] = []
    tries = 0
    while len(lines) < n_wires and tries < max_tries:
        tries += 1
        pts = _wire_curve(rng, hi, margin, length, segments)
        targets: list[int] = []
        if touching and lines and rng.random() < touch_probability:
            # cross a random wire: put a middle point of the new wire 2 r above a middle
            # point of the old one, along the normal to both tangents, then make it exact
            k = int(rng.integers(0, len(lines)))
            q = lines[k]
            iq = int(rng.integers(len(q) // 6, len(q) - len(q) // 6))
            ip = int(rng.integers(len(pts) // 6, len(pts) - len(pts) // 6))
            tq = q[min(iq + 1, len(q) - 1)] - q[max(iq - 1, 0)]
            tp = pts[min(ip + 1, len(pts) - 1)] - pts[max(ip - 1, 0)]
            nrm = np.cross(tq, tp)
            sn = np.linalg.norm(nrm) / (np.linalg.norm(tq) * np.linalg.norm(tp))
            if sn < 0.3:
                continue
            nrm = nrm / np.linalg.norm(nrm) * (1.0 if rng.random() < 0.5 else -1.0)
            pts = pts + (q[iq] + 2 * radius * nrm - pts[ip])
            moved = _touch_by_translation(pts, [k], lines, 2 * radius)
            if moved is None:
                continue
            pts, targets = moved, [k]
            if len(lines) > 1 and rng.random() < second_touch:
                gaps = [polyline_distance(pts, o) if j != k else np.inf for j, o in enumerate(lines)]
                j = int(np.argmin(gaps))
                if gaps[j] < 2 * radius + 12.0:
                    moved = _touch_by_translation(pts, [k, j], lines, 2 * radius)
                    if moved is not None:
                        pts, targets = moved, [k, j]
        if np.any(pts.min(axis=0) < margin) or np.any(pts.max(axis=0) > hi - margin):
            continue
        ok = True
        for j, other in enumerate(lines):
            d = polyline_distance(pts, other)
            if j in targets:
                ok = abs(d - 2 * radius) < 1e-6
            elif touching:
                ok = d >= 2 * radius + 1.0
            else:  # the original check (vertices, with half a segment's slack): seeds keep their scenes
                D = np.linalg.norm(pts[:, None, :] - other[None, :, :], axis=-1)
                ok = D.min() >= 2 * radius + 1.0 + 0.5 * np.linalg.norm(pts[1] - pts[0])
            if not ok:
                break
        if not ok or not _self_clear(pts, radius):
            continue
        contacts.extend((k, len(lines)) for k in targets)
        lines.append(pts)
    p0 = np.concatenate([ln[:-1] for ln in lines]) if lines else np.zeros((0, 3))
    p1 = np.concatenate([ln[1:] for ln in lines]) if lines else np.zeros((0, 3))
    rod = np.concatenate([np.full(len(ln) - 1, k) for k, ln in enumerate(lines)]) if lines else np.zeros(0, int)
    return GeneratedScene(tuple(shape), p0, p1, np.full(len(p0), float(radius)), rod, sorted(contacts), lines,
                          {"generator": "wire_tangle", "radius": radius, "n_wires": len(lines),
                           "segments": segments, "length": length, "seed": seed, "touching": bool(touching),
                           "n_contacts": len(contacts)})
