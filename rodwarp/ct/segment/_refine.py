"""Stage ``refine`` of segmentation: every rod fitted against the raw greyscale.

Every voxel within ``r + window_margin`` of a rod is assigned to the rod whose surface is
nearest (touching neighbours then trade equal amounts of blurred intensity, so they do not
pull the fit); slab-wise intensity centroids perpendicular to the axis give a robust straight
line; a blurred-disc fit of the radial profile gives the contrast and the blur, the median
intensity mass per unit length the radius; each end is fitted, sub-voxel, to the intensity
along the axis with the profile of a blurred capsule (or flat) end.  Rounds repeat for the
rods that still move; pieces that converge onto one rod are merged between rounds; rods too
short, too faint or of the wrong thickness are rejected (:func:`_check_rod`).

A binarised stack (``st.binary``: the volume is the rods' mask) has no blur to fit: its plateau
is 1 and its edge a one-voxel step (``_binary.MASK_EDGE_SIGMA``), and each rod's radius comes
from the distance transforms of the mask (``_binary.surface_radius``), stored as the mass per
unit length a rod of that radius holds, so that every later use of the mass reads it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rodwarp.ct.segment._binary import MASK_EDGE_SIGMA, SurfaceDistance, surface_radius
from rodwarp.ct.segment._levels import MIXED_RADIUS_CV, _Levels
from rodwarp.ct.segment._params import SegmentParams
from rodwarp.ct.segment._pasting import _gap_filler, _merge_lines
from rodwarp.ct.segment._profile import _axis_level, _blur_model, _end_weight, _fit_radial_profile
from rodwarp.ct.segment._reader import _Reader
from rodwarp.ct._voxels import _basis, _point_segment_distance, _unit, _window_voxels
from rodwarp.rodset import segment_distance


class _Rod:
    __slots__ = ("p0", "p1", "r", "plateau", "resid", "mass", "mass_r", "ok", "why", "prev", "own_r", "split_off")

    def __init__(self, p0, p1, r):
        self.p0 = np.asarray(p0, float)
        self.p1 = np.asarray(p1, float)
        self.r = float(r)
        self.plateau = np.nan
        self.resid = np.nan
        self.mass = np.nan      # median slab mass per unit length (normalised intensity x voxels^2)
        self.mass_r = np.nan    # radius from the mass: sqrt(mass / (pi C))
        self.ok = True
        self.why = ""
        self.own_r = False
        self.split_off = False  # split off a traced axis that held touching rods, not refined yet

    @property
    def length(self):
        return float(np.linalg.norm(self.p1 - self.p0))


#: when the fitted radius differs from the coarse one by more than this share, the first round's
#: axis moves are undone and redone with the fitted radius (bundles of touching rods: the coarse
#: radius 5.3 against 3.3 fitted pulled neighbours together, contact recall 0.46 on one seed)
REDO_RADIUS_CHANGE = 0.2


def _inside(o, rod) -> bool:
    """True when the middle of ``o`` lies inside ``rod``'s body: no genuine rod can, so ``o`` is
    a fragment or a fit across ``rod`` and must not take voxels from it."""
    return float(_point_segment_distance((0.5 * (o.p0 + o.p1))[None], rod.p0, rod.p1)[0]) < rod.r


def _neighbours(rods, reach):
    """For each rod, the indices of rods whose segments come within ``reach`` (plus radii)."""
    from scipy.spatial import cKDTree

    n = len(rods)
    nb = [[] for _ in range(n)]
    if n < 2:
        return nb
    P0 = np.array([r.p0 for r in rods])
    P1 = np.array([r.p1 for r in rods])
    R = np.array([r.r for r in rods])
    L = np.linalg.norm(P1 - P0, axis=1)
    mid = 0.5 * (P0 + P1)
    pairs = cKDTree(mid).query_pairs(float(L.max()) + reach + 2 * R.max(), output_type="ndarray")
    if len(pairs) == 0:
        return nb
    i, j = pairs[:, 0], pairs[:, 1]
    d = segment_distance(P0[i], P1[i], P0[j], P1[j])
    hit = d < reach + R[i] + R[j]
    for a, b in zip(i[hit], j[hit]):
        nb[a].append(int(b))
        nb[b].append(int(a))
    return nb


class _Refiner:
    def __init__(self, reader: _Reader, st: _Levels, P: SegmentParams, r_glob: float):
        self.reader = reader
        self.st = st
        self.P = P
        self.C = 1.0          # fitted contrast (plateau) relative to fg - bg
        self.mixed = False    # per-rod radii
        self.sigma = 1.0      # fitted blur
        self.r = r_glob       # global radius
        self.delta = None     # end offset
        self.scale = 1.0 / (st.fg - st.bg)
        # pieces shorter than a rejectable rod do not take voxels from their neighbours
        self.min_len = P.min_length * r_glob
        # a mask: signed distances to its surface give the radii; its edge is a voxel step
        self.surface = _Reader(SurfaceDistance(reader.vol)) if st.binary else None
        if st.binary:
            self.sigma = MASK_EDGE_SIGMA

    def _voxels(self, rod: _Rod, ext: float, R: float):
        u = _unit(rod.p1 - rod.p0)
        a = rod.p0 - ext * u
        b = rod.p1 + ext * u
        zyx, t, rho, dist = _window_voxels(a[::-1], b[::-1], R, self.reader.shape)
        t = t - ext
        v = (self.reader.gather(zyx) - self.st.bg) * self.scale
        xyz = zyx[:, ::-1].astype(np.float64)
        return xyz, t, rho, v, u

    def _other_dist(self, rods, nbs, xyz, t, rod, reach):
        """Surface distance to the nearest neighbour, for points whose distance could be below
        ``reach`` (others: inf).  ``t``: the points' axial coordinates along ``rod``."""
        best = np.full(len(xyz), np.inf)
        order = np.argsort(t, kind="stable")
        ts = t[order]
        u = (rod.p1 - rod.p0) / max(rod.length, 1e-12)
        for j in nbs:
            o = rods[j]
            if not o.ok or o.length < self.min_len or _inside(o, rod):
                continue
            # only points whose axial coordinate is near the neighbour's projection can be near it
            tj = ((o.p0 - rod.p0) @ u, (o.p1 - rod.p0) @ u)
            D = reach + o.r
            i0, i1 = np.searchsorted(ts, (min(tj) - D, max(tj) + D))
            if i1 <= i0:
                continue
            sel = order[i0:i1]
            d = _point_segment_distance(xyz[sel], o.p0, o.p1) - o.r
            best[sel] = np.minimum(best[sel], d)
        return best

    def refine_axis(self, rods, k, nbs, collect=None):
        rod = rods[k]
        r = rod.r
        R = r + self.P.window_margin
        xyz, t, rho, v, u = self._voxels(rod, 0.0, R)
        if len(v) == 0:
            rod.ok, rod.why = False, "outside"
            return
        other = self._other_dist(rods, nbs, xyz, t, rod, R)
        own = (rho - r) <= other
        # near a volume face keep only voxels whose mirror image through the axis is inside
        # too, so that the truncated window stays symmetric about the axis
        shp = np.asarray(self.reader.shape[::-1], float)
        pax = rod.p0 + np.clip(t, 0.0, rod.length)[:, None] * u
        mir = 2.0 * pax - xyz
        sym = np.all((mir >= 0.0) & (mir <= shp - 1.0), axis=1)
        own &= sym
        L = rod.length
        # perpendicular slabs of unit width, interior only (away from the caps)
        lo_t, hi_t = 1.0, L - 1.0
        if hi_t - lo_t < 2.0:
            lo_t, hi_t = 0.25 * L, 0.75 * L
        sel = own & (t >= lo_t) & (t <= hi_t)
        vv = np.clip(v, -1.0, 2.0)
        e1, e2 = _basis(u)
        w = xyz - rod.p0
        a = w @ e1
        b = w @ e2
        bins = np.floor(t - lo_t).astype(np.int64)
        nb = int(math.floor(hi_t - lo_t)) + 1
        inside = (t >= lo_t) & (t <= hi_t)
        # slabs whose window disc lies wholly inside the volume (the others give no radius)
        tc = lo_t + np.arange(nb) + 0.5
        pc = rod.p0 + tc[:, None] * u
        full = np.all((pc - R >= -0.5) & (pc + R <= shp - 0.5), axis=1)
        bi = bins[sel]
        ws = vv[sel]
        m = np.bincount(bi, weights=ws, minlength=nb)
        ma = np.bincount(bi, weights=ws * a[sel], minlength=nb)
        mb = np.bincount(bi, weights=ws * b[sel], minlength=nb)
        mt = np.bincount(bi, weights=ws * t[sel], minlength=nb)
        # lattice aliasing: a unit slab holds a varying number of voxels (1 or 2 rows for a
        # rod along a face diagonal); scale each slab's mass by expected / actual voxel count
        n_all = np.bincount(bins[inside & sym], minlength=nb)
        dens = np.where(n_all > 0, math.pi * R * R / np.maximum(n_all, 1), 0.0)
        m_corr = m * dens
        area0 = math.pi * r * r * self.C
        # until a rod has its own radius, a thin one in a scan of mixed radii holds less mass
        # than the global radius promises
        f_min = 0.15 if (self.st.mixed and not getattr(rod, "own_r", False)) else 0.4
        ok = (m_corr > f_min * area0) & (n_all > 0.3 * math.pi * R * R)
        if ok.sum() < 3:
            rod.ok, rod.why = False, "no interior"
            return
        ca, cb, ct, mm = ma[ok] / m[ok], mb[ok] / m[ok], mt[ok] / m[ok], m_corr[ok]
        keep = np.ones(len(ca), bool)
        for _ in range(3):
            W = mm[keep]
            T = ct[keep]
            tm = (W * T).sum() / W.sum()
            dt = T - tm
            den = (W * dt * dt).sum()
            am = (W * ca[keep]).sum() / W.sum()
            bm = (W * cb[keep]).sum() / W.sum()
            sa = (W * dt * (ca[keep] - am)).sum() / den if den > 0 else 0.0
            sb = (W * dt * (cb[keep] - bm)).sum() / den if den > 0 else 0.0
            res = np.hypot(ca - am - sa * (ct - tm), cb - bm - sb * (ct - tm))
            mad = float(np.median(res[keep]))
            new_keep = res <= max(4.0 * 1.4826 * mad, 0.3)
            new_keep &= (mm >= 0.6 * np.median(mm[full[ok]] if full[ok].any() else mm))
            if new_keep.sum() < 3 or np.array_equal(new_keep, keep):
                break
            keep = new_keep
        rod.resid = float(np.sqrt(np.mean(res[keep] ** 2)))
        fk = full[ok][keep]
        rod.mass = max(float(np.median(mm[keep][fk] if fk.any() else mm[keep])), 0.0)
        rod.mass_r = math.sqrt(rod.mass / (math.pi * self.C))
        c = rod.p0 + tm * u + am * e1 + bm * e2
        u_new = _unit(u + sa * e1 + sb * e2)
        t0 = (rod.p0 - c) @ u_new
        t1 = (rod.p1 - c) @ u_new
        rod.p0, rod.p1 = c + t0 * u_new, c + t1 * u_new
        if self.surface is not None:
            r_dt = self._surface_radius(xyz, own, c, u_new, t0, t1)
            if np.isfinite(r_dt):  # (else the voxel count's mass stands: it estimates the same)
                rod.mass = math.pi * self.C * r_dt * r_dt
                rod.mass_r = r_dt
        if collect is not None:  # radial profile about the updated axis
            s2 = own & inside
            w2 = xyz[s2] - c
            tt = w2 @ u_new
            rn = np.sqrt(np.maximum(np.einsum("ij,ij->i", w2, w2) - tt * tt, 0.0))
            collect.append((rn, v[s2]))

    def _surface_radius(self, xyz, own, c, u, t0, t1):
        """Radius (voxels) of a rod of a mask from the voxels it owns near its surface, away from
        its ends (its caps curve in), about the axis through ``c`` along ``u`` from ``t0`` to ``t1``."""
        tt = (xyz - c) @ u
        trim = min(self.r + 1.0, 0.25 * (t1 - t0))
        sel = own & (tt >= t0 + trim) & (tt <= t1 - trim)
        w = xyz[sel] - c
        rho = np.sqrt(np.maximum(np.einsum("ij,ij->i", w, w) - tt[sel] ** 2, 0.0))
        phi = self.surface.gather(xyz[sel][:, ::-1].astype(np.int64))
        return surface_radius(phi, rho)

    def set_end_model(self, r, sigma, capsule):
        """Tabulate the disc-mean axial profile of a blurred rod end (plateau 1, s outward from
        the end: cap centre or flat face) and its half-level offset."""
        rho_e = min(self.P.end_radius, max(0.5, 0.8 * r))
        rr = (np.arange(12) + 0.5) / 12 * rho_e
        w = rr * _end_weight(rr, rho_e)
        w = w / w.sum()
        plateau = float((_blur_model(-np.inf, rr, r, sigma, capsule) * w).sum())
        s_grid = np.linspace(-r - 4.0 * sigma - 2.0, r + 4.0 * sigma + 2.0, 241)
        prof = (_blur_model(s_grid[:, None], rr[None, :], r, sigma, capsule) * w).sum(1) / plateau
        self.end_s, self.end_m = s_grid, prof
        i = int(np.argmax(prof < 0.5))
        f = (prof[i - 1] - 0.5) / (prof[i - 1] - prof[i]) if i > 0 else 0.0
        self.delta = float(s_grid[i - 1] + f * (s_grid[i] - s_grid[i - 1])) if i > 0 else 0.0
        self.end_half_width = r + 3.0 * sigma + 1.0

    def _fit_end(self, centres, prof, weight, plateau, t_guess, side):
        """Least-squares end position: observed bins against the tabulated end profile."""
        from scipy.optimize import minimize_scalar

        sel = np.isfinite(prof) & (weight > 0) & (np.abs(centres - t_guess) <= self.end_half_width)
        if sel.sum() < 4 or not (plateau > 0):
            return t_guess
        c, y, w = centres[sel], prof[sel], weight[sel]

        def cost(te):
            m = np.interp(side * (c - te), self.end_s, self.end_m)
            return float((w * (y - plateau * m) ** 2).sum())

        res = minimize_scalar(cost, bounds=(t_guess - 1.5, t_guess + 1.5), method="bounded",
                              options={"xatol": 1e-4})
        return float(res.x) if res.success else t_guess

    def refine_ends(self, rods, k, nbs):
        rod = rods[k]
        r = rod.r
        rho_e = min(self.P.end_radius, max(0.5, 0.8 * r))
        ext = r + 3.0 * self.sigma + 3.0
        shp = np.asarray(self.reader.shape[::-1], float)
        for attempt in range(6):
            xyz, t, rho, v, u = self._voxels(rod, ext, rho_e)
            L = rod.length
            # inside another rod's body: not ours (ends touching a neighbour's side)
            excl = np.zeros(len(t), bool)
            order = np.argsort(t, kind="stable")
            ts = t[order]
            for j in nbs:
                o = rods[j]
                if not o.ok or o.length < self.min_len or _inside(o, rod):
                    continue
                uo = (o.p1 - o.p0) / o.length
                if abs(float(uo @ u)) > 0.985 and _point_segment_distance(
                        np.stack([o.p0, o.p1]), rod.p0 - 1e3 * u, rod.p1 + 1e3 * u).max() < r:
                    continue  # a collinear piece of this very rod: merged later, not a body
                tj = ((o.p0 - rod.p0) @ u, (o.p1 - rod.p0) @ u)
                D = o.r + 0.5
                i0, i1 = np.searchsorted(ts, (min(tj) - D, max(tj) + D))
                if i1 > i0:
                    sel = order[i0:i1]
                    excl[sel] |= _point_segment_distance(xyz[sel], o.p0, o.p1) < o.r + 0.5
            # unit bins anchored at the foot of the perpendicular from the origin, so that the
            # binning does not depend on where the ends currently are; smooth radial weights
            # and linear (cloud-in-cell) binning make the profile a smooth function of the
            # axis, so that the refinement converges to a reproducible fixed point
            tF = -float(rod.p0 @ u)
            b0 = int(math.floor(-ext - tF))
            nb = int(math.floor(L + ext - tF)) - b0 + 2
            x = t - tF - b0 - 0.5
            k0 = np.floor(x).astype(np.int64)
            f = x - k0
            wr = _end_weight(rho, rho_e)
            cnt = np.zeros(nb)
            cg = np.zeros(nb)
            sv = np.zeros(nb)
            own = (~excl).astype(np.float64)
            for kk, wb in ((k0, 1.0 - f), (k0 + 1, f)):
                inr = (kk >= 0) & (kk < nb)
                kk, ww = kk[inr], (wb * wr)[inr]
                cnt += np.bincount(kk, weights=ww, minlength=nb)
                cg += np.bincount(kk, weights=ww * own[inr], minlength=nb)
                sv += np.bincount(kk, weights=ww * own[inr] * v[inr], minlength=nb)
            mine = cg > 0.2 * np.maximum(cnt, 1e-12)
            prof = np.where(mine, sv / np.maximum(cg, 1e-12), 0.0)
            cg = np.where(mine, cg, 0.0)
            centres = b0 + np.arange(nb) + 0.5 + tF
            # the axis leaves the volume: the rod is cut by the field of view there
            pc = rod.p0 + centres[:, None] * u
            outside = np.any((pc < -0.5) | (pc > shp - 0.5), axis=1) | (cnt <= 0)
            prof = np.where(outside, np.nan, prof)
            inner = (centres > 0.2 * L) & (centres < 0.8 * L) & np.isfinite(prof)
            if inner.sum() < 1:
                inner = (centres > 0) & (centres < L) & np.isfinite(prof)
            if inner.sum() < 1:
                rod.ok, rod.why = False, "no profile"
                return
            plateau = float(np.median(prof[inner]))
            rod.plateau = plateau
            level = 0.5 * plateau
            mid = int(np.argmin(np.abs(centres - 0.5 * L)))
            new_t = []
            extend = False
            for side in (-1, 1):
                i = mid
                found = None
                while 0 <= i + side < nb:
                    j = i + side
                    if not np.isfinite(prof[j]):
                        found = centres[i]  # volume boundary: end at the last voxel inside
                        break
                    nxt = j + side
                    dip = (prof[j] < level and cg[j] > 0 and 0 <= nxt < nb and np.isfinite(prof[nxt])
                           and prof[nxt] >= level)
                    if prof[j] < level and not dip:  # (a single low bin inside a rod is noise)
                        f = (prof[i] - level) / (prof[i] - prof[j]) if prof[i] != prof[j] else 0.5
                        guess = centres[i] + side * f - side * self.delta
                        found = self._fit_end(centres, np.where(cg > 0, prof, np.nan), cg, plateau, guess, side)
                        break
                    i = j
                if found is None:
                    extend = True
                    found = centres[i]
                new_t.append(found)
            t0, t1 = new_t
            if t1 - t0 < 0.5:
                rod.ok, rod.why = False, "collapsed"
                return
            p0 = rod.p0 + t0 * u
            p1 = rod.p0 + t1 * u
            rod.p0, rod.p1 = p0, p1
            if not extend:
                return
            ext *= 2.0

    def contrast_fit(self, collect, r_fixed):
        rho = np.concatenate([c[0] for c in collect]) if collect else np.zeros(0)
        v = np.concatenate([c[1] for c in collect]) if collect else np.zeros(0)
        if len(rho) < 200:
            return
        if len(rho) > 3_000_000:
            sel = np.linspace(0, len(rho) - 1, 3_000_000).astype(np.int64)
            rho, v = rho[sel], v[sel]
        C, r, sg = _fit_radial_profile(rho, v, self.r, r_fixed)
        self.C, self.r, self.sigma = C, r, sg


def _dedupe_rods(rods, P, filled=None):
    """Drop failed rods and union duplicates / collinear pieces among the rest.

    Returns the rods kept, the number of merges and the reasons of the dropped rods (one per
    rod, in the rods' order).
    """
    good, failed = [], []
    for rod in rods:
        if rod.ok:
            good.append(rod)
        else:
            failed.append(rod.why)
    if len(good) < 2:
        return good, 0, failed
    r = float(np.median([g.r for g in good]))
    merged, nm, groups = _merge_lines([(g.p0, g.p1) for g in good], r, P.merge_angle,
                                      P.merge_distance * r, P.merge_gap * r, filled=filled)
    if nm == 0:
        return good, 0, failed
    out = []
    for (p0, p1), mem in zip(merged, groups):
        if len(mem) == 1:
            out.append(good[mem[0]])
        else:
            out.append(_Rod(p0, p1, good[mem[0]].r))
    return out, nm, failed


def _check_rod(rod, r_glob, C, P, sigma=None, mixed=False):
    """Mark a rod as failed when it is too short, too faint or of the wrong thickness.

    The faint test compares the axis plateau with what a rod of this radius shows under the
    fitted blur (``min_fill`` of it), so thin rods are judged by their own standard, not by
    the plateau of thick ones.  With mixed radii the length and radius tests use the rod's
    own radius and a wide range (0.3 to 3 times the median radius).
    """
    lo_r, hi_r = P.radius_range if not mixed else (min(P.radius_range[0], 0.3), max(P.radius_range[1], 3.0))
    r_own = rod.r if mixed else r_glob
    if rod.ok and rod.length < P.min_length * r_own:
        rod.ok, rod.why = False, "short"
    expect = C
    if sigma is not None:
        expect = C * _axis_level(r_own, sigma, min(P.end_radius, max(0.5, 0.8 * r_own)))
    if rod.ok and np.isfinite(rod.plateau) and rod.plateau < P.min_fill * expect:
        rod.ok, rod.why = False, "faint"
    if rod.ok and np.isfinite(rod.mass) and not (lo_r * r_glob <= math.sqrt(rod.mass / (math.pi * C)) <= hi_r * r_glob):
        rod.ok, rod.why = False, "radius"


@dataclass(frozen=True)
class RefineStats:
    """What the greyscale refinement (:func:`_refine`) measured, besides the rods.

    Attributes
    ----------
    radius_profile_fit : float or None
        Global rod radius from the blurred-disc fit of the radial profile (voxels), before
        the radius from the intensity mass per unit length replaces it; None for a mask.
    radius_cv : float
        Robust coefficient of variation (1.4826 MAD / median, dimensionless) of the rods' own radii
        from their mass per unit length; 0 with fewer than 3 rods.
    rounds : int
        Refinement rounds run (at most ``refine_iterations``).
    rod_refinements : int
        Rod refinements summed over the rounds (a rod counts once per round it was refined).
    contrast_fit : float
        Fitted rod plateau relative to the measured foreground - background (dimensionless).
    blur_sigma : float
        Fitted Gaussian blur of the image (voxels).
    end_offset : float
        Offset of a rod end from the half-level point along the axis, for the fitted radius,
        blur and end model (voxels).
    rejected : dict of str to int
        Rods dropped during refinement, by reason (``"no interior"``, ``"collapsed"``,
        ``"short"``, ..., and ``"duplicate"`` for pieces merged into another rod), in the
        order the reasons first occurred; reasons that never occurred are absent.
    touching_split : int
        Traced axes that held two or more touching rods (their mass and cross-section said so),
        each replaced by its rods (:func:`_split_touching_rods`).
    """

    radius_profile_fit: float
    radius_cv: float
    rounds: int
    rod_refinements: int
    contrast_fit: float
    blur_sigma: float
    end_offset: float
    rejected: dict
    touching_split: int = 0


def _set_radii(rods, ref, st, P, r_given) -> float:
    """The global radius, the mixed-radii switch and each rod's radius from the rods' masses;
    returns the robust cv of the rods' own radii (0 with fewer than 3 rods).

    The radius from the mass per unit length is unbiased by touching neighbours (the
    nearest-surface partition trades equal leaks); the profile shape is not.  Mixed radii are
    detected from the ridge, or from the spread of the rods' own radii.
    """
    masses = [rod.mass for rod in rods if rod.ok and np.isfinite(rod.mass)]
    if r_given is None and masses:
        ref.r = math.sqrt(float(np.median(masses)) / (math.pi * ref.C))
    ref.min_len = P.min_length * ref.r
    own = np.array([math.sqrt(rod.mass / (math.pi * ref.C)) for rod in rods
                    if rod.ok and np.isfinite(rod.mass) and rod.mass > 0])
    cv = 1.4826 * float(np.median(np.abs(own - np.median(own)))) / float(np.median(own)) if own.size >= 3 else 0.0
    if P.per_rod_radius is None:
        ref.mixed = r_given is None and (st.mixed or cv > MIXED_RADIUS_CV)
    else:
        ref.mixed = bool(P.per_rod_radius) and r_given is None
    for rod in rods:
        rod.r = ref.r
        if ref.mixed and np.isfinite(rod.mass) and rod.mass > 0:
            rod.r = float(np.clip(math.sqrt(rod.mass / (math.pi * ref.C)), 0.5, 3.0 * ref.r))
            rod.own_r = True
    return cv


def _single_mass(masses) -> float:
    """A single rod's intensity mass per unit length: the lightest well-populated cluster.

    Each rod's cluster is the rods within 15% of its mass; of the clusters holding at least half
    as many rods as the largest (and at least 3), the lightest one's median.  Touching rods
    traced as one (about twice the mass) and pieces cut by the volume's faces (lighter, few)
    then do not move it; a pile of mixed radii gets its thinnest common rod.
    """
    m = np.sort(np.asarray(masses, float))
    lo = np.searchsorted(m, m / 1.15, side="left")
    hi = np.searchsorted(m, m * 1.15, side="right")
    count = hi - lo
    need = max(0.5 * count.max(), min(3, count.max()))
    i = int(np.flatnonzero(count >= need)[0])
    return float(np.median(m[lo[i]:hi[i]]))


def _touching_groups(rods, fat, radius, max_members):
    """Groups of parallel rods (within 5 degrees) whose surfaces touch (within a voxel), each
    holding a candidate of ``fat``: lists of rod indices, the heaviest group first."""
    ok = [k for k, rod in enumerate(rods) if rod.ok]
    U = {k: _unit(rods[k].p1 - rods[k].p0) for k in ok}
    parent = {k: k for k in ok}

    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x

    nb = _neighbours([rods[k] for k in ok], 1.0)
    for i, js in enumerate(nb):
        a = ok[i]
        for j in js:
            b = ok[j]
            if a < b and abs(float(U[a] @ U[b])) > math.cos(math.radians(5.0)):
                d = float(segment_distance(rods[a].p0[None], rods[a].p1[None], rods[b].p0[None], rods[b].p1[None])[0])
                if d < radius[a] + radius[b] + 1.0:
                    parent[find(a)] = find(b)
    groups: dict[int, list] = {}
    for k in ok:
        groups.setdefault(find(k), []).append(k)
    fat_set = set(fat)
    out = [sorted(g, key=lambda k: (-rods[k].length, k)) for g in groups.values()
           if fat_set.intersection(g) and len(g) <= max_members]
    out.sort(key=lambda g: (-max(rods[k].mass for k in g if k in fat_set), g[0]))
    return out


#: rods of the lightest mass cluster examined for being bundles themselves, and the share of
#: them that must be for the cluster to count as bundles
CLUSTER_PROBES, CLUSTER_BUNDLED_SHARE = 6, 2.0 / 3.0


def _cluster_holds(rods, m1, ref, sample) -> int:
    """How many touching rods each rod of the lightest mass cluster holds: 1, or k = 2 or 3 when
    most of its longest rods' cross-sections are k touching discs of radius ``r1 / sqrt(k)``
    rather than one disc (a scan of thin rods all bundled: every trace is a bundle, and the
    lightest is no single rod; rodwarp's closest-packed bundles of radius 1.5 traced 8 of 28)."""
    from rodwarp.ct.segment._bundles import split_touching

    r1 = math.sqrt(m1 / (math.pi * ref.C))
    probe = sorted((rod for rod in rods if rod.ok and np.isfinite(rod.mass) and abs(rod.mass / m1 - 1.0) < 0.15
                    and rod.length >= 8.0 * r1), key=lambda rod: -rod.length)[:CLUSTER_PROBES]
    if len(probe) < 3:
        return 1
    best, best_n = 1, 0
    for k in (2, 3):
        rk = r1 / math.sqrt(k)
        n = 0
        need = math.ceil(CLUSTER_BUNDLED_SHARE * len(probe))
        for i, rod in enumerate(probe):
            if n + len(probe) - i < need:  # (the rest cannot make the share)
                break
            near = [(o.p0, o.p1, math.sqrt(max(o.mass, 0.0) / (math.pi * ref.C)) if np.isfinite(o.mass) else r1)
                    for o in rods if o is not rod and o.ok
                    and float(segment_distance(o.p0[None], o.p1[None], rod.p0[None], rod.p1[None])[0]) < 4.0 * r1]
            axes = split_touching(sample, [(rod.p0, rod.p1)], rk, ref.sigma, ref.C, near)
            n += axes is not None and len(axes) >= 2
        if n >= need and n > best_n:
            best, best_n = k, n
    return best


def _split_touching_rods(rods, ref, reader, st, r_given):
    """Traced axes that hold more touching rods than they are, replaced by those rods.

    Candidates hold at least :data:`~rodwarp.ct.segment._bundles.FAT_MASS_RATIO` times a single
    rod's mass per unit length.  Each candidate and the parallel rods touching it form a group,
    examined heaviest first (:func:`~rodwarp.ct.segment._bundles.split_touching`) with the rods
    around it modelled and taken off its cross-section: the rods split before it, groups kept
    whole at their own radii, the others at the single rods' radius (their own when thinner; a
    candidate not yet examined is left in the section).  A disc nearer another rod than any of
    the group's axes is that rod's, not a new one.  Rods split off are marked ``split_off``
    until refined.  Returns the rods and the number of groups split.
    """
    from rodwarp.ct.segment._bundles import FAT_MASS_RATIO, MAX_RODS, split_touching

    masses = [rod.mass for rod in rods if rod.ok and np.isfinite(rod.mass) and rod.mass > 0]
    if r_given is None and len(masses) < 2:
        return rods, 0
    m1 = math.pi * ref.C * r_given * r_given if r_given is not None else _single_mass(masses)
    if not m1 > 0:
        return rods, 0
    scale, bg = ref.scale, st.bg

    def sample(xyz):
        return (reader.trilinear(xyz) - bg) * scale

    if r_given is None:
        m1 = m1 / _cluster_holds(rods, m1, ref, sample)
    r1 = math.sqrt(m1 / (math.pi * ref.C))
    fat = [k for k, rod in enumerate(rods) if rod.ok and np.isfinite(rod.mass)
           and rod.mass >= FAT_MASS_RATIO * m1 and rod.length >= 4.0 * r1]
    if not fat:
        return rods, 0

    def own(rod):
        return math.sqrt(rod.mass / (math.pi * ref.C)) if np.isfinite(rod.mass) and rod.mass > 0 else r1

    radius = {k: own(rod) for k, rod in enumerate(rods)}
    groups = _touching_groups(rods, fat, radius, MAX_RODS - 1)
    waiting = {id(rods[k]) for g in groups for k in g}

    def model_radius(rod):
        return own(rod) if own(rod) < r1 or rod.mass >= FAT_MASS_RATIO * m1 else r1

    out = list(rods)
    n_split = 0
    reach = 4.0 * r1 + 3.0 * ref.sigma + 2.0
    for g in groups:
        mem = [rods[k] for k in g]
        waiting.difference_update(id(o) for o in mem)
        others = [o for o in out if o.ok and all(o is not q for q in mem)]
        near = [o for o in others if id(o) not in waiting and
                min(float(segment_distance(o.p0[None], o.p1[None], q.p0[None], q.p1[None])[0]) for q in mem) < reach]
        axes = split_touching(sample, [(q.p0, q.p1) for q in mem], r1, ref.sigma, ref.C,
                              [(o.p0, o.p1, model_radius(o)) for o in near])
        if axes is None:
            continue
        mine = []
        for a, b in axes:
            m = 0.5 * (a + b)[None]
            d_own = min(float(_point_segment_distance(m, q.p0, q.p1)[0]) for q in mem)
            if all(float(_point_segment_distance(m, o.p0, o.p1)[0]) > d_own for o in near):
                mine.append((a, b))
        if len(mine) < len(mem):  # (fewer discs than traced axes: the tracing stands)
            continue
        kids = []
        for a, b in mine:
            kid = _Rod(a, b, r1)
            kid.mass, kid.mass_r, kid.split_off = m1, r1, True
            kid.prev = (kid.p0.copy(), kid.p1.copy())
            kids.append(kid)
        gone = {id(q) for q in mem}
        out = [o for o in out if id(o) not in gone] + kids
        n_split += len(mine) > len(mem)
    return out, n_split


def _refine(reader, st, P, lines, progress):
    """Greyscale refinement until every rod moves less than ``refine_tol`` (at most
    ``refine_iterations`` rounds; a rod is refined again only while it or a neighbour moves).

    Returns the rods (dropped ones removed), the refiner (its fitted contrast ``C``, radius
    ``r``, blur ``sigma`` and ``mixed`` flag) and the :class:`RefineStats`.
    """
    r_given = 0.5 * P.diameter if P.diameter is not None else None
    rods = [_Rod(a, b, st.r0) for a, b in lines]
    ref = _Refiner(reader, st, P, st.r0)
    cap = P.end_model == "capsule"
    ref.set_end_model(st.r0, ref.sigma, cap)
    filled = _gap_filler(reader, st, st.r0)
    n_it = P.refine_iterations
    fit_it = 0
    active = set(range(len(rods)))
    n_refined = 0
    it = 0
    rejected: dict[str, int] = {}  # reason -> rods, in the order the reasons first occur
    r_profile = cv = None
    split_rods = 0
    fresh: set = set()  # rods split off a fat one: refined in the next round whatever they moved
    for it in range(n_it):
        if progress is not None:
            progress("refine", it, n_it)
        for rod in rods:
            rod.prev = (rod.p0.copy(), rod.p1.copy())
        nbl = _neighbours(rods, 2.0 * P.window_margin + 1.0)
        fit_now = it == fit_it
        if fit_now:
            active = set(range(len(rods)))
        collect = [] if fit_now and ref.surface is None else None
        for k in sorted(active):
            if rods[k].ok:
                ref.refine_axis(rods, k, nbl[k], collect)
        if fit_now:
            if ref.surface is None:  # (a mask has nothing to fit: contrast 1, a one-voxel edge)
                ref.contrast_fit(collect, r_given)
                r_profile = ref.r
            cv = _set_radii(rods, ref, st, P, r_given)
            ref.set_end_model(ref.r, ref.sigma, cap)
            if abs(ref.r / st.r0 - 1.0) > REDO_RADIUS_CHANGE:
                # the axes moved with a wrong radius (bundles inflate the coarse one: touching
                # rods then share one window and pull together): undo, and move them next round
                for rod in rods:
                    rod.p0, rod.p1 = rod.prev[0].copy(), rod.prev[1].copy()
        if it == fit_it + 1 and ref.surface is None:
            # (once duplicates are merged: two traces of one rod share its mass and look thin)
            rods, n_split = _split_touching_rods(rods, ref, reader, st, r_given)
            if n_split:
                split_rods += n_split
                fresh.update(id(rod) for rod in rods if rod.split_off)
                for rod in rods:
                    rod.split_off = False
                active = set(range(len(rods)))
                cv = _set_radii(rods, ref, st, P, r_given)
                ref.set_end_model(ref.r, ref.sigma, cap)
        nbl = _neighbours(rods, 2.0 * P.window_margin + 1.0)
        for k in sorted(active):
            if rods[k].ok:
                ref.refine_ends(rods, k, nbl[k])
        n_refined += len(active)
        if it >= fit_it:
            for k in active:
                _check_rod(rods[k], ref.r, ref.C, P, ref.sigma, ref.mixed)
                if ref.mixed and rods[k].ok and np.isfinite(rods[k].mass) and rods[k].mass > 0:
                    rods[k].r = float(np.clip(math.sqrt(rods[k].mass / (math.pi * ref.C)), 0.5, 3.0 * ref.r))
                    rods[k].own_r = True
        moved = {}
        for k, rod in enumerate(rods):
            if k in active:
                moved[id(rod)] = max(float(np.linalg.norm(rod.p0 - rod.prev[0])),
                                     float(np.linalg.norm(rod.p1 - rod.prev[1])))
        old_ids = {id(rod) for rod in rods}
        rods, nm, failed = _dedupe_rods(rods, P, filled)
        for why in failed:
            rejected[why] = rejected.get(why, 0) + 1
        if nm:
            rejected["duplicate"] = rejected.get("duplicate", 0) + nm
        # next round: rods that moved, new (merged) rods, and the neighbours of either
        hot = [k for k, rod in enumerate(rods)
               if id(rod) not in old_ids or id(rod) in fresh or moved.get(id(rod), 0.0) > P.refine_tol]
        fresh.clear()
        if it + 1 < n_it and hot:
            nbl = _neighbours(rods, 2.0 * P.window_margin + 1.0)
            active = set(hot)
            for k in hot:
                active.update(nbl[k])
        elif it >= fit_it + 1 and not hot:
            break
        else:
            active = set(range(len(rods)))
    if progress is not None:
        progress("refine", n_it, n_it)
    stats = RefineStats(radius_profile_fit=r_profile, radius_cv=cv, rounds=it + 1, rod_refinements=n_refined,
                        contrast_fit=ref.C, blur_sigma=ref.sigma, end_offset=ref.delta, rejected=rejected,
                         touching_split=split_rods)
    return rods, ref, stats
