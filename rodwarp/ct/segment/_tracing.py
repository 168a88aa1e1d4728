"""Stage ``detect`` of segmentation, cylinder fits and marching: every seed traced into a rod axis.

A seed is fitted by iterative intensity-weighted centroid/line fits inside a cylinder of one
radius around the current axis, then *marched*: the axis grows block by block while a small
disc on it stays filled, refitting as it grows.  An elongated cross-section is two rods side
by side (split in two); a cross-section much shallower than it is wide is a bundle (split by
:mod:`rodwarp.ct.segment._bundles`).  Foreground that no traced rod explains seeds a second round.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import NamedTuple

import numpy as np
from scipy import ndimage

from rodwarp.ct.segment._levels import _Levels
from rodwarp.ct.segment._params import SegmentParams
from rodwarp.ct.segment._seeds import _skeleton_seeds
from rodwarp.ct._voxels import _BlockSampler, _basis, _canonical, _disc_offsets, _point_segment_distance, _unit, _window_voxels


@dataclass
class TraceStats:
    """Counts from tracing one block (:func:`_detect_block`), or all blocks (:meth:`total`).

    Attributes
    ----------
    skeleton_voxels, skeleton_junctions : int
        Voxels of the binarised foreground's 3-D skeleton, and of its junctions (see
        :class:`rodwarp.ct.segment._seeds.SeedResult`).
    seeds : int
        Skeleton seeds traced (straight skeleton pieces).
    split : int
        Traces whose cross-section showed two rods side by side, split in two.
    bundles_split, bundle_rods : int
        Traces recognised as bundles of touching rods, and the rods traced in them.
    residual_seeds : int
        Seeds taken from foreground that no traced rod explained (the second round).
    seeds_turned : int
        Seeds traced along the image's own direction (:meth:`_BlockTrace.axis_direction`)
        because that trace is much longer than the skeleton piece's: a piece running across the
        rods of a raft.
    branch_voxels, bent_voxels, bent_branches : int
        Long skeleton branches judged for bending: their voxels, the voxels of those that bend
        smoothly, and how many do (``shape="auto"``).
    events : tuple of str
        Names of the optional counters (``split``, ``bundles_split``, ``bundle_rods``,
        ``residual_seeds``, ``seeds_turned``) that became non-zero, in the order they first did; a counter
        never incremented is not listed.  ``SegmentResult.quality`` lists exactly these, in
        this order.
    """

    skeleton_voxels: int = 0
    skeleton_junctions: int = 0
    seeds: int = 0
    split: int = 0
    bundles_split: int = 0
    bundle_rods: int = 0
    residual_seeds: int = 0
    branch_voxels: int = 0
    bent_voxels: int = 0
    bent_branches: int = 0
    seeds_turned: int = 0
    events: tuple[str, ...] = ()

    def _bump(self, name: str, n: int) -> None:
        setattr(self, name, getattr(self, name) + n)
        if name not in self.events:
            self.events = self.events + (name,)

    @property
    def bend_fraction(self) -> float:
        """Fraction (0 to 1) of the long skeleton branches' voxels that bend smoothly (0 without long branches)."""
        return self.bent_voxels / self.branch_voxels if self.branch_voxels else 0.0

    @classmethod
    def total(cls, parts) -> "TraceStats":
        """The counts of several blocks summed; ``events`` in the order they first occurred, block by block."""
        out = cls()
        for part in parts:
            for f in fields(cls):
                if f.name != "events":
                    setattr(out, f.name, getattr(out, f.name) + getattr(part, f.name))
            out.events = out.events + tuple(e for e in part.events if e not in out.events)
        return out


class TraceResult(NamedTuple):
    """What :func:`_detect_block` traced in one block.

    Attributes
    ----------
    lines : list of (p0, p1)
        Rod axes, each two (3,) end points in global ``(x, y, z)`` voxels.
    stats : TraceStats
        The block's counts.
    mask : ndarray of bool or None
        The binarised block when it is the whole volume (reused by the confidence stage).
    """

    lines: list
    stats: TraceStats
    mask: np.ndarray | None = None


#: a trace filling less than 0.4 of the fitting disc is a thin rod when the image on its axis
#: (median over slices, the probe disc) is at least this share of the plateau
THIN_AXIS_LEVEL = 0.6


#: a seed is turned to the image's own direction when the structure tensor's weakest
#: eigenvalue is below this share of its middle one (a rod: 0.0-0.1; a crossing or a blob: more)
AXIS_TENSOR_RATIO = 0.2
#: ... and the seed's direction is more than this (degrees) away from it
SEED_TURN_DEG = 20.0
#: ... and the trace along the image's direction is this many times longer than the seed's own
SEED_TURN_GAIN = 1.5


class _Tracer:
    """Coarse fits and marching on one block's smoothed, normalised image."""

    def __init__(self, g, origin_zyx, r0, P: SegmentParams):
        self.S = _BlockSampler(g, origin_zyx)
        self.r0 = r0
        self.P = P
        self.fit_offs = _disc_offsets(max(r0, 1.0))
        self.probe_offs = _disc_offsets(max(0.5 * r0, 0.75))
        self.mom_offs = _disc_offsets(1.6 * r0 + 1.0)

    mixed = False

    def _slices(self, c, u, ts, offs):
        e1, e2 = _basis(u)
        return (c + ts[:, None, None] * u + offs[None, :, 0, None] * e1 + offs[None, :, 1, None] * e2)

    def fit(self, c, u, t0, t1, n_iter, avoid=None):
        """Centroid/line fit on [t0, t1]; returns (c, u, t0, t1, fill) or None.

        ``avoid``: segments [(p0, p1)] of neighbours; samples nearer to one of them than to
        this axis are ignored (keeps two rods side by side apart).
        """
        offs = self.fit_offs
        rad = np.hypot(offs[:, 0], offs[:, 1])
        for _ in range(n_iter):
            if t1 - t0 < 1.0:
                mid = 0.5 * (t0 + t1)
                t0, t1 = mid - 0.5, mid + 0.5
            ts = np.arange(t0, t1 + 1e-9, 1.0)
            e1, e2 = _basis(u)
            pts = c + ts[:, None, None] * u + offs[None, :, 0, None] * e1 + offs[None, :, 1, None] * e2
            w = self.S(pts)
            w = np.where(np.isfinite(w), np.clip(w, 0.0, 1.0), 0.0)
            for q0, q1 in (avoid or ()):
                d = _point_segment_distance(pts.reshape(-1, 3), q0, q1).reshape(w.shape)
                w = np.where(d < rad[None, :], 0.0, w)
            m = w.sum(1)
            ok = m > 0.25 * len(offs)
            if ok.sum() < 2:
                return None
            a = (w[ok] * offs[:, 0]).sum(1) / m[ok]
            b = (w[ok] * offs[:, 1]).sum(1) / m[ok]
            tt = ts[ok]
            ww = m[ok]
            tm = (ww * tt).sum() / ww.sum()
            dt = tt - tm
            den = (ww * dt * dt).sum()
            am, bm = (ww * a).sum() / ww.sum(), (ww * b).sum() / ww.sum()
            sa = (ww * dt * (a - am)).sum() / den if den > 0 else 0.0
            sb = (ww * dt * (b - bm)).sum() / den if den > 0 else 0.0
            p0, p1 = c + t0 * u, c + t1 * u
            c_new = c + tm * u + am * e1 + bm * e2
            u_new = _unit(u + sa * e1 + sb * e2)
            t0, t1 = (p0 - c_new) @ u_new, (p1 - c_new) @ u_new
            c, u = c_new, u_new
        fill = float(m.sum() / (len(ts) * len(offs)))
        return c, u, float(t0), float(t1), fill

    def march(self, c, u, t0, t1, max_len, avoid=None):
        P = self.P
        B = int(P.march_block)
        for side in (1.0, -1.0):
            while True:
                tend = t1 if side > 0 else t0
                ts = tend + side * np.arange(1, B + 1, dtype=np.float64)
                pts = self._slices(c, u, ts, self.probe_offs)
                v = self.S(pts)
                fill = np.where(np.all(np.isfinite(v), axis=1), v.mean(1), -1.0)
                bad = np.nonzero(fill < P.march_fill)[0]
                k = int(bad[0]) if len(bad) else B
                if side > 0:
                    t1 += k
                else:
                    t0 -= k
                if k < B or (t1 - t0) > max_len:
                    break
                res = self.fit(c, u, t0, t1, 1, avoid)
                if res is None:
                    break
                c, u, t0, t1, _ = res
        return c, u, t0, t1

    def axis_level(self, c, u, t0, t1):
        """Median over slices of the mean image on the probe disc (half the coarse radius)."""
        ts = np.arange(t0, t1 + 1e-9, 1.0)
        v = self.S(self._slices(c, u, ts, self.probe_offs))
        v = np.where(np.isfinite(v), v, 0.0)
        return float(np.median(v.mean(1))) if len(v) else 0.0

    def moments(self, c, u, t0, t1):
        """Median over slices of the cross-section second moments (2x2) about the axis."""
        ts = np.arange(t0, t1 + 1e-9, 1.0)
        pts = self._slices(c, u, ts, self.mom_offs)
        w = self.S(pts)
        w = np.where(np.isfinite(w), np.clip(w, 0.0, 1.0), 0.0)
        m = w.sum(1)
        ok = m > 0.25 * len(self.fit_offs)
        if ok.sum() < 1:
            return None
        w, m = w[ok], m[ok]
        o = self.mom_offs
        mx = (w * o[:, 0]).sum(1) / m
        my = (w * o[:, 1]).sum(1) / m
        sxx = (w * o[:, 0] ** 2).sum(1) / m
        syy = (w * o[:, 1] ** 2).sum(1) / m
        sxy = (w * o[:, 0] * o[:, 1]).sum(1) / m
        return np.array([[np.median(sxx), np.median(sxy)], [np.median(sxy), np.median(syy)]]), \
            np.array([np.median(mx), np.median(my)])

    def trace(self, c, u, t0, t1, max_len, avoid=None):
        P = self.P
        res = self.fit(c, u, t0, t1, P.fit_iterations, avoid)
        if res is None:
            return None
        c, u, t0, t1, fill = res
        # a thinner rod fills less of the fitting disc: with mixed radii accept down to a
        # quarter (a rod of half the coarse radius); without, a trace that fills under 0.4 is
        # still a thin rod when its axis is bright (radii 2-5 can spread the distance ridge too
        # little to be called mixed: rods of r 2.0-2.3 against a coarse 3.3 fill 0.31-0.40 of
        # the disc, with axes at 0.6-0.8 of the plateau)
        if fill < 0.25 or (fill < 0.4 and not self.mixed and self.axis_level(c, u, t0, t1) < THIN_AXIS_LEVEL):
            return None
        c, u, t0, t1 = self.march(c, u, t0, t1, max_len, avoid)
        res = self.fit(c, u, t0, t1, P.fit_iterations, avoid)
        if res is None:
            return None
        return res


def _lines_cover(lines, pt, radius):
    """True if pt lies within ``radius`` of one of the segments in lines [(p0, p1), ...]."""
    if not lines:
        return False
    A = np.array([l[0] for l in lines])
    Bp = np.array([l[1] for l in lines])
    d = Bp - A
    L2 = np.maximum((d * d).sum(1), 1e-300)
    t = np.clip(((pt - A) * d).sum(1) / L2, 0.0, 1.0)
    dist = np.linalg.norm(pt - A - t[:, None] * d, axis=1)
    return bool(np.any(dist < radius))


def _rasterize(lines, shape_zyx, origin_zyx, radius):
    """Boolean block mask of voxels within ``radius`` (one value, or one per segment) of any segment."""
    cov = np.zeros(shape_zyx, bool)
    o = np.asarray(origin_zyx)
    rad = np.broadcast_to(np.asarray(radius, float), (len(lines),))
    for (p0, p1), R in zip(lines, rad):
        zyx, _, _, _ = _window_voxels(p0[::-1] - o, p1[::-1] - o, float(R), shape_zyx)
        if len(zyx):
            cov[zyx[:, 0], zyx[:, 1], zyx[:, 2]] = True
    return cov


def _kid_segment(kd):
    """The axis (p0, p1) of a child trace ``(c, u, t0, t1)``."""
    return (kd[0] + kd[2] * kd[1], kd[0] + kd[3] * kd[1])


class _BlockTrace:
    """Tracing of one block: the smoothed image, its mask, and the rod axes traced so far.

    Seeds are traced in order (:meth:`run`); each seed's trace becomes a bundle's rods
    (:meth:`_trace_bundle`), two rods side by side (:meth:`_split_pair`) or one rod.  Axes are
    ``(p0, p1)`` in global ``(x, y, z)`` voxels.
    """

    def __init__(self, raw: np.ndarray, origin_zyx, st: _Levels, P: SegmentParams):
        g = ndimage.gaussian_filter(raw, P.smooth_sigma) if P.smooth_sigma > 0 else raw
        scale = 1.0 / (st.fg_smooth - st.bg)  # the smoothed rod plateau is 1
        self.g = (g - np.float32(st.bg)) * np.float32(scale)
        self.mask = self.g > (st.threshold - st.bg) * scale
        self.raw, self.origin_zyx, self.st, self.P = raw, origin_zyx, st, P
        self.r0 = st.r0
        self.tr = _Tracer(self.g, origin_zyx, self.r0, P)
        self.tr.mixed = st.mixed
        self.max_len = float(np.linalg.norm(raw.shape)) + 2.0
        self.o_xyz = np.asarray(origin_zyx, float)[::-1]
        self.lines: list[tuple[np.ndarray, np.ndarray]] = []
        self.stats = TraceStats()
        self.r_kid = self.r0     # radius of the last bundle's rods
        self.kid_r: dict[int, float] = {}  # lines traced as rods of a bundle: their own radius
        self._raw_norm = None

    def cover_radius(self) -> np.ndarray:
        """Radius (voxels) each line covers; a bundle's rods cover only themselves, so that one
        the fit missed is seeded again."""
        return np.array([self.kid_r.get(i, self.r0) + 1.5 for i in range(len(self.lines))])

    def _raw_sampler(self):
        """The raw block's samples normalised (background 0, rods 1), made on first use."""
        if self._raw_norm is None:
            rs, bg, scale = _BlockSampler(self.raw, self.origin_zyx), self.st.bg, 1.0 / (self.st.fg - self.st.bg)
            self._raw_norm = lambda q: (rs(q) - bg) * scale
        return self._raw_norm

    def _bundle_offsets(self, c, u, t0, t1):
        """Offsets (k >= 3, 2) of the rods of a bundle around axis c, u, or None."""
        from rodwarp.ct.segment._bundles import cross_section, fit_discs, looks_bundled

        r0 = self.r0
        sample = self._raw_sampler()
        e1, e2 = _basis(u)
        # a cheap screen first (the median of 4 cross-sections: almost every trace is one rod),
        # the 16-section median only for a suspected bundle
        img, g1 = cross_section(sample, c, u, e1, e2, t0, t1, 2.5 * r0 + 2.0, h=1.0, n_pos=4)
        if img is None or not looks_bundled(img, 1.0):
            return None
        img, g1 = cross_section(sample, c, u, e1, e2, t0, t1, 2.5 * r0 + 2.0, h=1.0)
        if img is None or not looks_bundled(img, 1.0):
            return None
        fit = fit_discs(img, g1)
        if fit is None or len(fit[0]) < 3:
            return None
        # the kids' own radius (a bundle's binarised outline inflates the coarse one)
        self.r_kid = min(r0, max(0.75, fit[1]))
        return fit[0]

    def _trace_bundle(self, c2, u2, a, b, kids_xy) -> bool:
        """A bundle: one child per rod, fitted alternately, each ignoring its siblings.

        Returns True when the seed is done (rods of the bundle traced, or the bundle traced
        before), False when it is to be judged as one rod.
        """
        P, lines, max_len, r_kid = self.P, self.lines, self.max_len, self.r_kid
        e1, e2 = _basis(u2)
        kids = [(c2 + x * e1 + y * e2, u2, a, b) for x, y in kids_xy]

        def sibs(i_k):
            return [_kid_segment(kd) for j, kd in enumerate(kids) if j != i_k and kd is not None]

        # the children are traced with discs of their own radius
        tk = _Tracer(self.g, self.origin_zyx, r_kid, P)
        for rnd in range(2):
            for i_k in range(len(kids)):
                if kids[i_k] is not None:
                    fk = tk.fit(*kids[i_k], P.fit_iterations, sibs(i_k))
                    kids[i_k] = None if fk is None else fk[:4]
        got = covered = 0
        for i_k in range(len(kids)):
            if kids[i_k] is None:
                continue
            if _lines_cover(lines, kids[i_k][0], 0.75 * r_kid):
                covered += 1
                continue
            ch = tk.trace(*kids[i_k], max_len, sibs(i_k))
            if ch is None or ch[3] - ch[2] < 3.0 * r_kid or _lines_cover(lines, ch[0], 0.75 * r_kid):
                continue
            kids[i_k] = ch[:4]
            lines.append(_kid_segment(kids[i_k]))
            self.kid_r[len(lines) - 1] = r_kid
            got += 1
        if got:
            self.stats._bump("bundles_split", 1)
            self.stats._bump("bundle_rods", got)
            return True
        return bool(covered)  # a bundle traced before, seen again: its middle is no rod

    def _split_pair(self, c2, u2, a, b) -> bool:
        """Two rods side by side when the cross-section is elongated: a child traced on each
        side (children are not split).  Returns True when at least one child was traced."""
        P, tr, lines, r0, max_len = self.P, self.tr, self.lines, self.r0, self.max_len
        mom = tr.moments(c2, u2, a, b)
        if mom is None:
            return False
        ev, evec = np.linalg.eigh(mom[0])
        if not ev[1] - ev[0] > P.split_anisotropy * r0 * r0:
            return False
        e1, e2 = _basis(u2)
        d2 = evec[0, 1] * e1 + evec[1, 1] * e2
        off = max(math.sqrt(ev[1] - ev[0]), r0)
        # the two children are fitted alternately, each ignoring the voxels nearer to its sibling
        kids = [(c2 + off * d2, u2, a, b), (c2 - off * d2, u2, a, b)]
        for rnd in range(2):
            for i_k in (0, 1):
                if kids[i_k] is None or kids[1 - i_k] is None:
                    continue
                fk = tr.fit(*kids[i_k], P.fit_iterations, [_kid_segment(kids[1 - i_k])])
                kids[i_k] = None if fk is None else fk[:4]
        got = 0
        for i_k in (0, 1):
            if kids[i_k] is None:
                continue
            sib = [_kid_segment(kids[1 - i_k])] if kids[1 - i_k] is not None else None
            if _lines_cover(lines, kids[i_k][0], 0.75 * r0):
                continue
            ch = tr.trace(*kids[i_k], max_len, sib)
            if ch is None or ch[3] - ch[2] < 3.0 * r0 or _lines_cover(lines, ch[0], 0.75 * r0):
                continue
            kids[i_k] = ch[:4]
            lines.append(_kid_segment(kids[i_k]))
            got += 1
        if got:
            self.stats._bump("split", 1)
        return bool(got)

    def axis_direction(self, c):
        """The rods' direction at ``c`` (global xyz) from the image's gradient structure tensor,
        or None where the image there is not one-directional.

        Around a rod, and inside a raft of parallel touching rods, every gradient is normal to
        the rods, so the tensor's weakest direction is theirs; the skeleton of a raft wider than
        it is thick runs across it (a medial surface thinned to lines) and cannot tell.
        """
        r0 = self.r0
        h = int(math.ceil(2.0 * r0 + 2.0))
        q = np.round(np.asarray(c, float)[::-1] - np.asarray(self.origin_zyx, float)).astype(int)
        lo = np.maximum(q - h, 0)
        hi = np.minimum(q + h + 1, self.g.shape)
        if np.any(hi - lo < 5):
            return None
        sub = self.g[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]
        gz, gy, gx = np.gradient(sub)
        zz, yy, xx = np.meshgrid(*(np.arange(a, b) - qq for a, b, qq in zip(lo, hi, q)), indexing="ij")
        w = np.exp(-(zz * zz + yy * yy + xx * xx) / (2.0 * (1.5 * r0) ** 2))
        G = np.stack([gx, gy, gz], -1).reshape(-1, 3)  # (x, y, z)
        T = (G * w.reshape(-1, 1)).T @ G
        ev, vec = np.linalg.eigh(T)
        if not ev[0] < AXIS_TENSOR_RATIO * ev[1]:
            return None
        return _canonical(vec[:, 0])

    def run(self, seed_list) -> None:
        """Trace each seed ``(c, u, t0, t1, weight)`` (global xyz) not yet covered by a line."""
        r0 = self.r0
        for c, u, t0, t1, _ in seed_list:
            if _lines_cover(self.lines, c, 0.75 * r0):
                continue
            res = self.tr.trace(c, u, t0, t1, self.max_len)
            # a seed across the rods (the skeleton of a raft of touching rods) traced along them
            # too: the longer trace by far wins (across a raft it ends at the raft's edge; a rod
            # lying across the raft keeps its own, as long as along the raft)
            v = self.axis_direction(c)
            if v is not None and abs(float(v @ u)) < math.cos(math.radians(SEED_TURN_DEG)):
                alt = self.tr.trace(c, v, -2.0 * r0, 2.0 * r0, self.max_len)
                if alt is not None and (res is None or alt[3] - alt[2] > SEED_TURN_GAIN * (res[3] - res[2])):
                    res = alt
                    self.stats._bump("seeds_turned", 1)
            if res is None:
                continue
            c2, u2, a, b, fill = res
            if b - a < 3.0 * r0:  # a rod crossed sideways is about 2 r long
                continue
            kids_xy = self._bundle_offsets(c2, u2, a, b)
            if kids_xy is not None and self._trace_bundle(c2, u2, a, b, kids_xy):
                continue
            if self._split_pair(c2, u2, a, b):
                continue
            self.lines.append((c2 + a * u2, c2 + b * u2))

    def residual_seeds(self) -> list:
        """Seeds of the foreground no line explains: one per eroded component big enough to be a
        rod, longest first (empty when there is none)."""
        r0, o_xyz = self.r0, self.o_xyz
        cov = _rasterize(self.lines, self.mask.shape, self.origin_zyx, self.cover_radius())
        resid = self.mask & ~cov
        resid = ndimage.binary_erosion(resid, iterations=1)
        lab, nlab = ndimage.label(resid, structure=np.ones((3, 3, 3)))
        if nlab == 0:
            return []
        sizes = np.bincount(lab.ravel())
        min_vox = max(10, int(0.5 * math.pi * max(r0 - 1, 0.5) ** 2 * 4 * r0))
        new = []
        objs = ndimage.find_objects(lab)
        for k in range(1, nlab + 1):
            if sizes[k] < min_vox:
                continue
            sl = objs[k - 1]
            q = np.argwhere(lab[sl] == k) + np.array([s.start for s in sl])
            q = q[:, ::-1].astype(np.float64) + o_xyz
            c = q.mean(0)
            _, _, vt = np.linalg.svd(q - c, full_matrices=False)
            u = _canonical(vt[0])
            t = (q - c) @ u
            new.append((c, u, float(t.min()), float(t.max()), len(q)))
        new.sort(key=lambda s: (-(s[3] - s[2]), -s[4], tuple(np.round(s[0], 6))))
        return new


def _detect_block(raw: np.ndarray, origin_zyx, st: _Levels, P: SegmentParams,
                  volume_shape=None) -> TraceResult:
    """Trace rods in one block: their axes (p0, p1) in global xyz, and the block's counts.

    Parameters
    ----------
    raw : ndarray (z, y, x)
        The block's grey values (the chunk and its halo).
    origin_zyx : tuple of int
        Index of the block's first voxel in the volume.
    st : _Levels
        The volume's levels (stage ``stats``).
    P : SegmentParams
        Knobs.
    volume_shape : tuple of int, optional
        The whole volume's shape: skeleton branches cut by an inner block face are not ends,
        and the mask is kept when the block is the whole volume.
    """
    bt = _BlockTrace(raw, origin_zyx, st, P)
    cut = None
    if volume_shape is not None:
        cut = [(origin_zyx[a] > 0, origin_zyx[a] + raw.shape[a] < volume_shape[a]) for a in range(3)]
    sr = _skeleton_seeds(bt.mask, st.r0, P, cut)
    bt.stats = TraceStats(skeleton_voxels=sr.skeleton_voxels, skeleton_junctions=sr.skeleton_junctions,
                          seeds=len(sr.seeds), branch_voxels=sr.branch_voxels, bent_voxels=sr.bent_voxels,
                          bent_branches=sr.bent_branches)
    bt.run([(s[0] + bt.o_xyz, s[1], s[2], s[3], s[4]) for s in sr.seeds])
    for _ in range(P.residual_passes):
        new = bt.residual_seeds()
        if not new:
            break
        bt.stats._bump("residual_seeds", len(new))
        bt.run(new)
    # the foreground no final rod explains is measured after refinement (stage ``doubt``), on
    # this mask when the block is the whole volume
    whole = volume_shape is not None and tuple(raw.shape) == tuple(volume_shape)
    return TraceResult(bt.lines, bt.stats, bt.mask if whole else None)
