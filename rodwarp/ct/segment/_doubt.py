"""Where the trace is unsure: a confidence per traced rod or filament, and the foreground no
trace explains.

Run by :func:`rodwarp.ct.segment_volume` after either path (straight rods or curved
filaments), in one pass over the prepared volume, a block of slices at a time:

* the volume is smoothed (``smooth_sigma``) and binarised at the threshold of stage ``stats``, as
  detection saw it;
* the voxels within ``r + 1.5`` of a traced axis (each rod its own radius) are *explained*;
  the rest of the foreground is *unexplained*: a missed rod, a rod traced too short, a fused
  mass of fibres, debris.  Its share, its connected regions (largest first, centres in
  working voxels) and its projections (for ``qa_confidence.png``) are returned;
* each traced axis is sampled every voxel.  Three things lower its confidence:

  - **support**: the share of the axis on the foreground (a trace cutting across a gap, or
    fitted through noise, is off it);
  - **crowding**: the share of a ring of radius ``r + 2.5`` about the axis that is unexplained
    foreground (a lone rod's ring is background; a rod traced through a fused mass, or
    beside a neighbour nobody traced, is surrounded by it);
  - **open ends**: an end past which the unexplained foreground continues (the filament goes on:
    broken, or cut short at a crossing);

  and a radius far from the median (a thick trace is often two fused fibres), and, for
  curved traces with the binarised volume at hand, a cross-section wider than thick: the
  trace's radius (from its intensity mass) over the inscribed radius of its cross-section (half
  the shortest foreground chord through the axis in the normal plane, median along the axis),
  relative to the median trace's, above :data:`WIDE_RATIO` (fused fibres traced as one, or a
  flattened fibre).  The confidence is ``support x (1 - crowding) x 0.75^open_ends``
  (x 0.7 for the radius, x 0.6 when wider than thick), from 0 to 1; a rod below
  :data:`DOUBT_CONFIDENCE` is *doubtful*, with its reasons in words.

The cost is one Gaussian smoothing and one rasterisation of the traces over the volume (a few
per cent of a segmentation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

__all__ = ["Doubt", "assess", "DOUBT_CONFIDENCE"]

#: a rod or filament below this confidence is doubtful (named in ``quality.flags`` and the QA)
DOUBT_CONFIDENCE = 0.7
#: explained: within this many voxels of a trace's surface (as ``foreground_explained``)
EXPLAIN_MARGIN = 1.5
#: the crowding ring lies this far outside a rod's surface (voxels): beyond its own blurred edge
RING_MARGIN = 2.5
#: an end is open when unexplained foreground lies this far past it (voxels beyond the cap)
END_MARGIN = 2.5
#: radius outside this range of the median's: doubtful (thick traces are often fused fibres)
RADIUS_RANGE = (0.6, 1.6)
#: blocks of this many slices
BLOCK = 64
#: a curved trace whose radius (from its intensity mass) over its cross-section's inscribed
#: radius is this many times the median trace's is wider than thick: fused fibres traced as
#: one, or a flattened fibre
WIDE_RATIO = 1.35


@dataclass(frozen=True)
class Doubt:
    """What :func:`assess` measured (per rod arrays in the rod set's order).

    Attributes
    ----------
    confidence : ndarray (n,)
        0 to 1; below :data:`DOUBT_CONFIDENCE` a rod is doubtful.
    support : ndarray (n,)
        Share of the axis (sampled every voxel) on the binarised foreground.
    crowding : ndarray (n,)
        Share of the ring of radius ``r + 2.5`` about the axis on unexplained foreground.
    open_ends : ndarray (n,) int
        Ends (0, 1 or 2) past which unexplained foreground continues.
    doubts : list of list of str
        Per rod, the reasons in words (empty: none).
    foreground_voxels, unexplained_voxels : int
        Binarised foreground, and the part of it farther than ``r + 1.5`` from every trace.
    regions : list of dict
        Connected unexplained regions at least a rod's cross-section in size, largest first (at
        most 20): ``centre`` (x, y, z, working voxels) and ``voxels``.
    n_regions : int
        Number of such regions.
    wide : ndarray (n,) or None
        Curved traces in a volume held whole: the trace's radius over its cross-section's
        inscribed radius (median along the axis); above :data:`WIDE_RATIO` times the median
        trace's, the trace is wider than thick (fused fibres traced as one, a flattened fibre)
        and its confidence is multiplied by 0.6.  Zeros otherwise.
    mip_z, mip_y : ndarray (2, ...) of uint16
        Projections along z (y, x) and along y (z, x): voxels of foreground ([0]) and of
        unexplained foreground ([1]) along each ray (for ``qa_confidence.png``).
    """

    confidence: np.ndarray
    support: np.ndarray
    crowding: np.ndarray
    open_ends: np.ndarray
    doubts: list
    foreground_voxels: int
    unexplained_voxels: int
    regions: list = field(default_factory=list)
    n_regions: int = 0
    mip_z: np.ndarray | None = None
    mip_y: np.ndarray | None = None
    wide: np.ndarray | None = None

    @property
    def unexplained_fraction(self) -> float:
        """Unexplained share (0 to 1) of the binarised foreground (0 without foreground)."""
        return self.unexplained_voxels / self.foreground_voxels if self.foreground_voxels else 0.0

    @property
    def doubtful(self) -> np.ndarray:
        """Indices of the doubtful rods."""
        return np.flatnonzero(self.confidence < DOUBT_CONFIDENCE)

    def summary(self) -> dict:
        """The ``quality.unexplained`` entry of summary.json."""
        return {"fraction": self.unexplained_fraction, "foreground_voxels": self.foreground_voxels,
                "unexplained_voxels": self.unexplained_voxels, "regions": self.n_regions,
                "largest_regions": self.regions[:10], "traces": int(len(self.confidence)),
                "doubtful": int(len(self.doubtful)),
                "doubt_confidence": DOUBT_CONFIDENCE}


#: the kind of each doubt sentence :func:`assess` writes, by how the sentence begins
DOUBT_KINDS = (("axis off the foreground", "axis off the foreground"),
               ("the foreground continues", "foreground continues past an end"),
               ("radius", "radius far from the median"),
               ("cross-section", "wider than thick (fused or flattened)"))


def doubt_kind(sentence: str) -> str:
    """The kind of one doubt sentence (a trace's ``doubts`` entry), for counting them by reason."""
    if "untraced foreground" in sentence:
        return "untraced foreground around it"
    for start, kind in DOUBT_KINDS:
        if sentence.startswith(start):
            return kind
    return sentence.split(" (")[0].split(" for ")[0]


def _unit_rows(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _axis_samples(rods, step: float = 1.0):
    """Points every ``step`` along each axis (x, y, z), their rod, their unit tangents, and each
    rod's two end points with their outward unit tangents (2 n, 3) each."""
    from rodwarp.ct.segment._score import resample_polyline

    pts, owner, tang, ends, out = [], [], [], [], []
    for k in range(rods.n_rods):
        q = resample_polyline(rods.rod(k), step)
        pts.append(q)
        owner.append(np.full(len(q), k))
        tang.append(_unit_rows(np.gradient(q, axis=0)))
        for a, b in ((q[0], q[min(3, len(q) - 1)]), (q[-1], q[max(len(q) - 4, 0)])):
            ends.append(a)
            out.append(a - b)
    return np.concatenate(pts), np.concatenate(owner), np.concatenate(tang), np.array(ends), _unit_rows(np.array(out))


def _ring(r: float, n: int = 12) -> np.ndarray:
    a = np.linspace(0.0, 2 * math.pi, n, endpoint=False)
    return np.stack([np.cos(a), np.sin(a)], 1) * r


def _inscribed_radii(mask: np.ndarray, pts: np.ndarray, t: np.ndarray, r_max: float,
                     n_dir: int = 8, step: float = 0.5) -> np.ndarray:
    """Half the shortest foreground chord through each axis sample (x, y, z) in its normal plane
    (``n_dir`` directions, chords walked ``step`` voxels at a time up to ``r_max`` each way): the
    radius of the largest disc the cross-section holds there."""
    ref = np.where(np.abs(t[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = _unit_rows(np.cross(t, ref))
    e2 = np.cross(t, e1)
    a = np.linspace(0.0, math.pi, n_dir, endpoint=False)
    steps = np.arange(step, r_max + step, step)
    shape = np.asarray(mask.shape)
    out = np.empty(len(pts))
    for c0 in range(0, len(pts), 4096):
        p, u1, u2 = pts[c0:c0 + 4096], e1[c0:c0 + 4096], e2[c0:c0 + 4096]
        d = np.cos(a)[None, :, None] * u1[:, None, :] + np.sin(a)[None, :, None] * u2[:, None, :]  # (m, n_dir, 3)
        chord = np.zeros((len(p), n_dir))
        for sign in (1.0, -1.0):
            run = np.ones((len(p), n_dir), bool)
            w = np.zeros((len(p), n_dir))
            for s_ in steps:
                q = p[:, None, :] + sign * s_ * d
                idx = np.rint(q[..., ::-1]).astype(np.int64)
                ok = np.all((idx >= 0) & (idx < shape), axis=-1)
                on = np.zeros(ok.shape, bool)
                on[ok] = mask[idx[ok][:, 0], idx[ok][:, 1], idx[ok][:, 2]]
                run &= on
                w += run * step
                if not run.any():
                    break
            chord += w
        out[c0:c0 + 4096] = 0.5 * (chord.min(1) + step)  # the last on-voxel reaches half a step on
    return out


def assess(reader, st, rods, P, block: int = BLOCK, mask=None) -> Doubt:
    """Confidence of every traced rod and the foreground no trace explains.

    Parameters
    ----------
    reader : rodwarp.ct.segment._reader._Reader
        The prepared volume (z, y, x).
    st : rodwarp.ct.segment._levels._Levels
        Levels of stage ``stats`` (``threshold``, ``bg``, ``fg_smooth``).
    rods : RodSet
        The traced rods or filaments in working voxels (x, y, z), with their radii.
    P : SegmentParams
        ``smooth_sigma``.
    block : int
        Slices per block (memory: about 20 bytes a voxel of a block).
    mask : ndarray of bool (z, y, x), optional
        The binarised volume, when detection kept it (then nothing is read or smoothed).

    Returns
    -------
    Doubt
    """
    from rodwarp.ct.segment._tracing import _rasterize

    shape = reader.shape
    n = rods.n_rods
    radii = np.asarray(rods.radii, float) if n else np.zeros(0)
    p0, p1, seg_rod = rods.segments() if n else (np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, int))
    seg_r = radii[seg_rod] + EXPLAIN_MARGIN if n else np.zeros(0)
    if n:
        pts, owner, t, end_at, end_t = _axis_samples(rods)
    else:
        pts, t, end_at, end_t = (np.zeros((0, 3)),) * 4
        owner = np.zeros(0, int)
    # ring points about every axis sample, in its normal plane
    ref = np.where(np.abs(t[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    e1 = _unit_rows(np.cross(t, ref))
    e2 = np.cross(t, e1)
    ring = _ring(1.0)
    rr = (radii[owner] + RING_MARGIN)[:, None, None]
    ring_pts = pts[:, None, :] + rr * (ring[None, :, 0, None] * e1[:, None, :] + ring[None, :, 1, None] * e2[:, None, :])
    end_pts = end_at + (np.repeat(radii, 2) + END_MARGIN)[:, None] * end_t
    if mask is not None and tuple(mask.shape) != tuple(shape):
        mask = None

    halo = int(math.ceil(4 * P.smooth_sigma)) + 1
    fg = un = 0
    mip_z = np.zeros((2,) + shape[1:], np.uint16)
    mip_y = np.zeros((2, shape[0], shape[2]), np.uint16)
    down = []
    thr = np.float32(st.threshold)
    zmin_seg = np.minimum(p0[:, 2], p1[:, 2]) - seg_r if n else np.zeros(0)
    zmax_seg = np.maximum(p0[:, 2], p1[:, 2]) + seg_r if n else np.zeros(0)

    class _Lookup:
        """Nearest-voxel values of a block's arrays at fixed points, the points sorted by slice
        so that each block reads only its own."""

        def __init__(self, q):
            idx = np.rint(q.reshape(-1, 3)[:, ::-1]).astype(np.int64)
            ok = np.all(idx >= 0, 1) & (idx[:, 0] < shape[0]) & (idx[:, 1] < shape[1]) & (idx[:, 2] < shape[2])
            self.order = np.flatnonzero(ok)[np.argsort(idx[ok, 0], kind="stable")]
            self.idx = idx[self.order]
            self.z = self.idx[:, 0]
            self.out = np.zeros(len(idx), bool)

        def take(self, z0, z1, vol):
            a, b = np.searchsorted(self.z, (z0, z1))
            i = self.idx[a:b]
            self.out[self.order[a:b]] = vol[i[:, 0] - z0, i[:, 1], i[:, 2]]

    look_axis, look_ring, look_end = _Lookup(pts), _Lookup(ring_pts), _Lookup(end_pts)

    for z0 in range(0, shape[0], block):
        z1 = min(shape[0], z0 + block)
        if mask is not None:
            mb = mask[z0:z1]
        else:
            lo, hi = max(0, z0 - halo), min(shape[0], z1 + halo)
            raw = reader.read((lo, 0, 0), (hi, shape[1], shape[2]))
            g = ndimage.gaussian_filter(raw, P.smooth_sigma) if P.smooth_sigma > 0 else raw
            mb = g[z0 - lo:z1 - lo] > thr
            del raw, g
        if n:
            sel = np.flatnonzero((zmax_seg >= z0 - 1) & (zmin_seg <= z1))
            lines = [(p0[i], p1[i]) for i in sel]
            cov = _rasterize(lines, mb.shape, (z0, 0, 0), seg_r[sel]) if len(sel) else np.zeros(mb.shape, bool)
        else:
            cov = np.zeros(mb.shape, bool)
        unex = mb & ~cov
        fg += int(np.count_nonzero(mb))
        nu = int(np.count_nonzero(unex))
        un += nu
        mip_z[0] += mb.sum(0, dtype=np.uint16)
        mip_y[0, z0:z1] = mb.sum(1, dtype=np.uint16)
        if nu:
            mip_z[1] += unex.sum(0, dtype=np.uint16)
            mip_y[1, z0:z1] = unex.sum(1, dtype=np.uint16)
            down.append(np.argwhere(unex) + (z0, 0, 0))
        look_axis.take(z0, z1, mb)
        look_ring.take(z0, z1, unex)
        look_end.take(z0, z1, mb)
    # regions of unexplained foreground (on the 2x grid), at least a rod's cross-section in size
    regions, n_regions = [], 0
    if down:
        # 2 x 2 x 2 cells holding unexplained voxels, over the box that holds them
        c2 = np.concatenate(down, 0) // 2
        lo2 = c2.min(0)
        D = np.zeros(tuple(c2.max(0) - lo2 + 1), bool)
        D[tuple((c2 - lo2).T)] = True
        lab, nl = ndimage.label(D, structure=np.ones((3, 3, 3), bool))
        if nl:
            sizes = np.bincount(lab.ravel(), minlength=nl + 1)[1:] * 8
            r_med = float(np.median(radii)) if n else float(st.r0)
            min_vox = max(8, int(math.pi * r_med ** 2 * 2 * r_med))  # a rod piece as long as it is wide
            big = np.flatnonzero(sizes >= min_vox)
            n_regions = int(len(big))
            if len(big):
                cen = ndimage.center_of_mass(D, lab, big + 1)
                order = np.argsort(-sizes[big], kind="stable")[:20]
                for o in order:
                    c = (np.asarray(cen[o]) + lo2) * 2 + 0.5  # back to working voxels (z, y, x)
                    regions.append({"centre": [float(c[2]), float(c[1]), float(c[0])], "voxels": int(sizes[big[o]])})
    # per rod
    count = np.maximum(np.bincount(owner, minlength=n), 1)
    support = np.bincount(owner, weights=look_axis.out, minlength=n) / count
    crowding = np.bincount(owner, weights=look_ring.out.reshape(ring_pts.shape[:2]).mean(1), minlength=n) / count
    open_ends = look_end.out.reshape(-1, 2).sum(1).astype(int)
    r_med = float(np.median(radii)) if n else 0.0
    conf = support * (1.0 - crowding) * 0.75 ** open_ends
    # curved traces (polylines) in a volume held whole: is the cross-section as thick as wide?
    wide = np.zeros(n)
    if n and mask is not None and int(np.max(np.diff(rods.offsets))) > 2:
        r_in = _inscribed_radii(mask, pts, t, 2.0 * float(np.max(radii)) + 3.0)
        r_in_med = ndimage.median(r_in, owner, np.arange(n)) if n else np.zeros(0)
        wide = radii / np.maximum(np.asarray(r_in_med, float), 0.5)
    # relative to the median trace's: the mass radius of a thin blurred fibre exceeds its
    # binarised inscribed radius by a share that depends on blur and threshold, not on fusion
    wide_med = float(np.median(wide)) if n else 0.0
    doubts = []
    for k in range(n):
        why = []
        if support[k] < 0.9:
            why.append(f"axis off the foreground for {100 * (1 - support[k]):.0f}% of its length")
        if crowding[k] > 0.1:
            why.append(f"{100 * crowding[k]:.0f}% of its surroundings is untraced foreground "
                       f"(fused fibres or a missed neighbour)")
        if open_ends[k]:
            why.append(f"the foreground continues past {open_ends[k]} end{'s' if open_ends[k] > 1 else ''} "
                       f"(broken, or cut short)")
        if r_med > 0 and not (RADIUS_RANGE[0] <= radii[k] / r_med <= RADIUS_RANGE[1]):
            conf[k] *= 0.7
            why.append(f"radius {radii[k] / r_med:.1f} x the median")
        if wide_med > 0 and wide[k] > WIDE_RATIO * wide_med:
            conf[k] *= 0.6
            why.append(f"cross-section {wide[k] / wide_med:.1f} x as wide for its thickness as the "
                       f"median trace's (fused fibres traced as one, or a flattened fibre)")
        doubts.append(why if conf[k] < DOUBT_CONFIDENCE else [])
    return Doubt(confidence=np.clip(conf, 0.0, 1.0), support=support, crowding=crowding, open_ends=open_ends,
                 doubts=doubts, wide=wide, foreground_voxels=fg, unexplained_voxels=un, regions=regions,
                 n_regions=n_regions, mip_z=mip_z, mip_y=mip_y)
