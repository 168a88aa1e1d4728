"""The fields of the lab's pressed packings against the authors' CT fields, like for like.

Both sides go through one rule set (docs/experiments.md, "The fields against the authors' CT, like
for like"):

- the authors' convention (``rodwarp analyze --convention authors``, docs/fields.md) for n, e, e2,
  S and c, on their grid (centres from R to the extent less R, steps of h = R / 2), R = sqrt(d l);
  the simulated rods resampled to edges of ``--edge`` diameters (the CT centrelines' edge length
  is not published: e2 / e, which grows with the edge length, is reported on both sides as the
  check);
- phi: the CT's as published; the simulation's the exact clipped volume (the text convention),
  on the same centres;
- the same region rule (:func:`rodwarp.analysis.packing_regions`): each packing's own axis,
  radius and height from its n field; the core within 0.55 of its radius, between 15% and 70%
  of its height; the rim the rest of that band;
- e per rod pair ball by ball (:func:`rodwarp.analysis.pair_entanglement`), its median and mean
  over the balls with two rods or more.

The simulated packings are ``rodwarp simulate --protocol lab --strains 0,0.05,0.1,0.15`` runs
(``scripts/lab_experiments.py run --set press``, ``press-frictionless``, ``press-ct``,
``press-wide``), which write the pressed rods at each strain (``rods_press<E>.npz``).

    python scripts/ct_like_for_like.py --runs RUNS_DIR --paper-fields DIR [--edge 4] [--cache DIR]

Writes ``benchmarks/results/ct_like_for_like.{json,md}`` and ``ct_like_for_like.png``. Each
packing's analysis is cached (``--cache``, default ``RUNS_DIR/../ct_like_for_like_cache``), so a
rerun only computes what is new.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results"

ALPHAS = (38, 66, 76, 100)
STRAINS = (0.0, 0.05, 0.1, 0.15)
#: the sets of scripts/lab_experiments.py compared here, and what each one changes
SETS = {"press": "cylinder Rc = l, filled to 1 l; walls mu 0.2",
        "press-frictionless": "as press, the cylinder's wall and the piston frictionless",
        "press-ct": "the CT's container (150 mm across) filled to 100 mm",
        "press-wide": "cylinder Rc = 2 l, filled to 2 l (alpha 38)"}
#: the CT's voxel (m): Materials and Methods, "X-ray Computerized Tomography imaging"
VOXEL_M = 78.22e-6
#: tracing noise tried on the simulated centrelines, in CT voxels (the straightness control)
NOISE_VOXELS = (0.5, 1.0, 2.0)
#: bows (rod diameters at mid-length) tried on the simulated rods (the straightness control)
BOWS_D = (0.5, 1.0, 2.0)
#: edge lengths (d) of the sensitivity check
EDGES = (2.0, 4.0, 8.0)
REGIONS = ("core", "rim")


def region_stats(fields: dict, mask: np.ndarray) -> dict:
    """The statistics of one region: balls, mean n, phi, S (mean, median), c, e, cv_e, e per pair
    (median, mean; balls of two rods or more), e2 / e (median; balls with e > 0)."""
    from rodwarp.analysis import pair_entanglement

    e = fields["e"][mask]
    n = fields["n"][mask]
    pe = pair_entanglement(e, n)
    pe = pe[np.isfinite(pe)]
    pos = e > 0
    phi = fields["phi"][mask]
    phi = phi[np.isfinite(phi)]  # NaN where the text fields were not computed (the controls)
    out = {"balls": int(mask.sum()), "n": float(n.mean()), "phi": float(phi.mean()) if phi.size else float("nan"),
           "S": float(fields["S"][mask].mean()), "S_median": float(np.median(fields["S"][mask])),
           "c": float(fields["c"][mask].mean()), "e": float(e.mean()),
           "cv_e": float(e.std() / e.mean()) if e.mean() > 0 else float("nan"),
           "e_pair_median": float(np.median(pe)) if len(pe) else float("nan"),
           "e_pair_mean": float(pe.mean()) if len(pe) else float("nan"),
           "e2_over_e": float(np.median(fields["e2"][mask][pos] / e[pos])) if pos.any() else float("nan"),
           # cv_e's two parts: how the rods per ball vary (density) and how e per pair does
           "cv_n": float(n.std() / n.mean()) if n.mean() > 0 else float("nan"),
           "cv_e_pair": float(pe.std() / pe.mean()) if len(pe) and pe.mean() > 0 else float("nan")}
    if "e_text" in fields:
        et = fields["e_text"][mask]
        pt = pair_entanglement(et, fields["n_text"][mask])
        pt = pt[np.isfinite(pt)]
        out.update({"e_text": float(et.mean()), "cv_e_text": float(et.std() / et.mean()) if et.mean() > 0 else
                    float("nan"), "e_pair_text_median": float(np.median(pt)) if len(pt) else float("nan")})
    return out


#: Fig. 2's histogram bins of S (the authors' S lies in [-1/2, 1]) and quantiles of c over its mean
S_BINS = np.linspace(-0.5, 1.0, 61)
C_QUANTILES = np.linspace(0.0, 1.0, 101)


def figure_data(fields: dict) -> dict:
    """Fig. 2-3's quantities of one packing over its occupied balls (n > 0, as the authors'
    statistics count them): p(S) and the distribution of c / mean c, the tangles (balls above e_lb = Q3 + 1.5 IQR,
    26-connected) and the z-profiles of phi, S, c / mean c, e and n (means over each layer's
    occupied balls; z in m above the plate)."""
    from rodwarp.analysis import find_tangles, outlier_bound

    occ = fields["n"] > 0
    S, c, e = fields["S"][occ], fields["c"][occ], fields["e"][occ]
    cm = float(c.mean()) if c.size else float("nan")
    h = float(fields["x"][1] - fields["x"][0])
    lb = outlier_bound(e)["e_lb"]
    _, tangles = find_tangles(np.where(occ, fields["e"], np.nan), occ, lb, spacing=h)
    big = tangles[0] if tangles else None
    prof = {}
    count = np.maximum(occ.sum(axis=(1, 2)), 1)
    for name in ("phi", "S", "c", "e", "n"):
        v = np.where(occ, np.nan_to_num(fields[name], nan=0.0), 0.0)
        prof[name] = (v.sum(axis=(1, 2)) / count / (cm if name == "c" else 1.0)).tolist()
    return {"p_S": np.histogram(S, bins=S_BINS, density=True)[0].tolist(),
            # c is a count over a constant: a histogram of it aliases, its quantiles do not
            "q_c": np.quantile(c / cm, C_QUANTILES).tolist(),
            "median_S": float(np.median(S)), "mean_c": cm, "e_lb": float(lb), "n_tangles": len(tangles),
            "largest_xi_over_L": big["xi_over_L"] if big else None, "percolates": bool(big and big["percolates"]),
            "z": [float(v) for v in fields["z"]], "profiles": prof,
            "cv_e_all": float(e.std() / e.mean()), "mean_e_all": float(e.mean()), "balls": int(occ.sum())}


def regional(fields: dict) -> dict:
    """Regions (:func:`rodwarp.analysis.packing_regions`), their statistics, and Fig. 2-3's data."""
    from rodwarp.analysis import packing_regions

    reg = packing_regions(fields["n"], fields["x"], fields["y"], fields["z"])
    out = {"geometry": reg.as_dict()}
    for name in REGIONS:
        out[name] = region_stats(fields, getattr(reg, name))
    out["fig"] = figure_data(fields)
    return out


# ----------------------------------------------------------------------------- the CT side


def ct_fields(data: Path, alpha: int, strain: float) -> dict | None:
    """The authors' published fields of one packing (lengths in m)."""
    f = data / f"alpha{alpha}_epsilon{int(round(strain * 100)):02d}.npz"
    if not f.is_file():
        return None
    d = np.load(f)
    out = {k: np.asarray(d[k], dtype=np.float64) for k in ("n", "e", "e2", "s", "c", "phi")}
    out["S"] = out.pop("s")
    for k in ("x", "y", "z"):
        out[k] = np.asarray(d["c" + k], dtype=np.float64) * VOXEL_M
    out["R"] = float(d["R"]) * VOXEL_M
    return out


def c_check(f: dict, geometry: dict) -> dict:
    """What the authors' c rule gives on average over a packing's occupied balls, against the
    published mean: each contact lies in about V_ball / h^3 balls, so mean c is about
    V_cyl / (occupied balls h^3), V_cyl the packing's bounding cylinder (here its footprint's
    diameter and its top plus R: the vertices' extents, which the rule uses, are not published)."""
    occ = f["n"] > 0
    h = float(f["x"][1] - f["x"][0])
    top = float(f["z"][occ.any(axis=(1, 2))].max()) + f["R"]
    v_cyl = np.pi * (2.0 * geometry["radius"]) ** 2 * top / 4.0
    return {"rule_mean_c": float(v_cyl / (occ.sum() * h**3)), "published_mean_c": float(f["c"][occ].mean())}


# ----------------------------------------------------------------------------- the simulated side


def resampled(rods, edge_d: float, noise_m: float = 0.0, seed: int = 0):
    """``rods`` resampled to edges of about ``edge_d`` diameters, interior vertices moved by an
    isotropic Gaussian of ``noise_m`` per axis when given (a traced centreline's noise).

    The authors' rules keep whole edges by their first vertex, so their fields depend on the edge
    length (docs/fields.md); rigid rods are stored as one edge each, which no ball would keep."""
    from rodwarp.rodset import RodSet

    polys = []
    for i in range(rods.n_rods):
        pts = rods.points[rods.offsets[i]:rods.offsets[i + 1]]
        arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
        k = max(2, int(round(arc[-1] / (edge_d * 2 * rods.radii[i]))) + 1)
        t = np.linspace(0.0, arc[-1], k)
        polys.append(np.stack([np.interp(t, arc, pts[:, j]) for j in range(3)], axis=1))
    out = RodSet.from_polylines(polys, radii=rods.radii, units=rods.units)
    if noise_m > 0:
        rng = np.random.default_rng(seed)
        pts = out.points.copy()
        o = out.offsets
        inner = np.ones(len(pts), bool)
        inner[o[:-1]] = False
        inner[o[1:] - 1] = False
        pts[inner] += rng.normal(0.0, noise_m, size=(int(inner.sum()), 3))
        out = out.with_points(pts)
    return out


def bowed(rods, bow_d: float, seed: int = 0):
    """``rods`` bent into a half-sine bow of ``bow_d`` diameters at mid-length, each in a random
    direction across its axis (a rod not quite straight; ends fixed)."""
    rng = np.random.default_rng(seed)
    pts = rods.points.copy()
    o = rods.offsets
    for i in range(rods.n_rods):
        p = pts[o[i]:o[i + 1]]
        axis = p[-1] - p[0]
        length = np.linalg.norm(axis)
        axis /= length
        v = rng.normal(size=3)
        v -= v.dot(axis) * axis
        v /= np.linalg.norm(v)
        s = (p - p[0]) @ axis / length
        p += np.outer(bow_d * 2 * rods.radii[i] * np.sin(np.pi * np.clip(s, 0, 1)), v)
    return rods.with_points(pts)


def sim_fields(rods, container_m: float, edge_d: float, noise_m: float = 0.0, text: bool = True,
               bow_d: float = 0.0) -> dict:
    """The pressed packing's fields on the authors' grid over the cylinder's box, from the plate
    to the piston (m): n, e, e2, S, c by the authors' rules; phi (and e, n) by the text's."""
    from rodwarp.analysis import compute_fields
    from rodwarp.analysis._authors import authors_field_arrays, authors_grid

    d = 2.0 * float(rods.radii[0])
    length = float(np.median(np.linalg.norm(rods.points[rods.offsets[1:] - 1] - rods.points[rods.offsets[:-1]],
                                            axis=1)))
    R = float(np.sqrt(d * length))
    h = R / 2.0
    top = float(rods.attrs["piston_height_m"])
    dom = np.array([[-container_m, -container_m, 0.0], [container_m, container_m, top]])
    x, y, z = authors_grid(dom, R, h)
    rs = resampled(rods, edge_d, noise_m)
    if bow_d > 0:
        rs = bowed(rs, bow_d)
    s0, s1, rod = rs.segments()
    a = authors_field_arrays(s0, s1, rod, np.asarray(rods.contacts.point, np.float64), x, y, z, R)
    out = {"n": a["n"], "e": a["e"], "e2": a["e2"], "S": a["S"], "c": a["c"], "x": x, "y": y, "z": z, "R": R,
           "phi": np.full(a["e"].shape, np.nan)}
    if text:
        # the text's grid is centred in its domain: a domain R beyond the authors' first and last
        # centres puts two of its centres (R = 2 h) before theirs, on theirs
        tdom = np.array([[x[0] - R, y[0] - R, z[0] - R], [x[-1] + R, y[-1] + R, z[-1] + R]])
        f = compute_fields(rods, radius=R, spacing=h, domain=tdom, keep_outside=True, contacts=rods.contacts,
                           device="cpu")
        idx = []
        for mine, theirs in ((f.x, x), (f.y, y), (f.z, z)):
            i = np.searchsorted(mine, theirs[0] - 1e-9 * R)
            if not (len(mine) >= i + len(theirs) and np.allclose(mine[i:i + len(theirs)], theirs, atol=1e-9 * R)):
                raise RuntimeError("the text grid does not hold the authors' centres")
            idx.append(slice(i, i + len(theirs)))
        sub = (idx[2], idx[1], idx[0])
        out["phi"] = np.asarray(f.phi)[sub]
        out["e_text"] = np.asarray(f.e)[sub]
        out["n_text"] = np.asarray(f.n)[sub]
    return out


def run_info(folder: Path) -> dict:
    s = json.loads((folder / "summary.json").read_text())
    p = s["parameters"]
    return {"run": folder.name, "alpha": int(round(s["alpha"])), "seed": int(s["seed"]), "n_rods": int(s["n_rods"]),
            "length_m": float(s["length"]), "container_m": float(p["container_radius"]) * float(s["length"]),
            "wall_mu": p.get("wall_mu"), "mu": p["mu"], "rod_model": s["rod_model"],
            "contact_law": s["contact_law"]["name"], "strains": s["lab"]["strains"]}


def cached(cache: Path, key: str, compute) -> dict:
    """The fields ``compute()`` returns (arrays and numbers), computed once and kept under
    ``cache/key.npz`` (float32 arrays, written atomically); the statistics are taken from them
    at each report, so a new statistic needs no recomputation."""
    f = cache / f"{key}.npz"
    if f.is_file():
        with np.load(f) as d:
            return {k: (float(d[k]) if d[k].ndim == 0 else np.asarray(d[k], dtype=np.float64)) for k in d.files}
    out = compute()
    cache.mkdir(parents=True, exist_ok=True)
    tmp = f.with_name(f.stem + ".tmp.npz")
    np.savez_compressed(tmp, **{k: (np.asarray(v, dtype=np.float64) if np.ndim(v) <= 1 else
                                    np.asarray(v, dtype=np.float32)) for k, v in out.items()})
    tmp.replace(f)
    return {k: (float(v) if np.ndim(v) == 0 else np.asarray(v, dtype=np.float64)) for k, v in out.items()}


def analyse_runs(runs: Path, cache: Path, edge: float, log) -> list[dict]:
    """Every finished pressed run under ``runs``: its regions' statistics at each strain."""
    import rodwarp

    rows = []
    for folder in sorted(p for p in runs.iterdir() if p.is_dir()):
        kind = folder.name.split("_alpha")[0]
        if kind not in SETS or not (folder / "summary.json").is_file():
            continue
        info = run_info(folder)
        for st in info["strains"]:
            src = folder / st.get("rods", f"rods_{st['stage']}.npz")
            if not src.is_file():
                continue

            def compute(src=src, info=info):
                t0 = time.perf_counter()
                f = sim_fields(rodwarp.load(src), info["container_m"], edge)
                f["wall_s"] = time.perf_counter() - t0
                return f

            key = f"{folder.name}_{st['stage']}_edge{edge:g}"
            log(f"{key}")
            res = regional(cached(cache, key, compute))
            rows.append({**{k: v for k, v in info.items() if k != "strains"}, "set": kind,
                         "strain": float(st["strain"]), "strain_reached": float(st["strain_reached"]), **res})
    return rows


def controls(runs: Path, cache: Path, edge: float, log) -> dict:
    """The edge-length sensitivity and the tracing-noise control on the press set's seed-0 poured
    packings (strain 0)."""
    import rodwarp

    out = {"edges": [], "noise": [], "bow": []}
    for alpha in ALPHAS:
        folder = runs / f"press_alpha{alpha}_seed0"
        src = folder / "rods_press0.npz"
        if not src.is_file():
            continue
        info = run_info(folder)
        rods = rodwarp.load(src)
        for e in EDGES:
            key = f"{folder.name}_press0_edge{e:g}"
            log(key)
            res = regional(cached(cache, key, lambda e=e: sim_fields(rods, info["container_m"], e)))
            out["edges"].append({"alpha": alpha, "edge_d": e, **{r: res[r] for r in REGIONS}})
        for nv in NOISE_VOXELS:
            key = f"{folder.name}_press0_edge{edge:g}_noise{nv:g}"
            log(key)
            res = regional(cached(cache, key, lambda nv=nv: sim_fields(rods, info["container_m"], edge,
                                                                       noise_m=nv * VOXEL_M, text=False)))
            out["noise"].append({"alpha": alpha, "noise_voxels": nv, "noise_d": nv * VOXEL_M * alpha /
                                 info["length_m"], **{r: res[r] for r in REGIONS}})
        for b in BOWS_D:
            key = f"{folder.name}_press0_edge{edge:g}_bow{b:g}"
            log(key)
            res = regional(cached(cache, key, lambda b=b: sim_fields(rods, info["container_m"], edge, text=False,
                                                                     bow_d=b)))
            out["bow"].append({"alpha": alpha, "bow_d": b, **{r: res[r] for r in REGIONS}})
    return out


def structureless(runs: Path, cache: Path, edge: float, alphas, seeds, log) -> list[dict]:
    """The floor of cv_e a packing without structure gives: the press set's rods (N, l, d) placed
    by random sequential addition, uniform and isotropic, in the same cylinder up to the poured
    packing's top (seed 0, strain 0), through the same fields and regions."""
    import rodwarp
    from rodwarp.experiments._packing import random_packing
    from rodwarp.rodset import detect_contacts

    out = []
    for alpha in alphas:
        folder = runs / f"press_alpha{alpha}_seed0"
        src = folder / "rods_press0.npz"
        if not src.is_file():
            continue
        info = run_info(folder)
        ref = rodwarp.load(src)
        top = float(ref.attrs["piston_height_m"])
        rc, l = info["container_m"], info["length_m"]
        for seed in seeds:
            key = f"rsa_alpha{alpha}_seed{seed}_edge{edge:g}"
            log(key)

            def compute(seed=seed):
                t0 = time.perf_counter()
                rods = random_packing(info["n_rods"], l, l / alpha, (2 * rc, 2 * rc, top), cylinder=rc, seed=seed,
                                      progress=False)
                placed = time.perf_counter() - t0
                rods = rods.with_points(rods.points - np.array([rc, rc, 0.0]))
                rods.contacts = detect_contacts(rods)
                rods.attrs["piston_height_m"] = top
                res = sim_fields(rods, rc, edge)
                res.update({"place_s": placed, "wall_s": time.perf_counter() - t0})
                return res

            res = regional(cached(cache, key, compute))
            out.append({"alpha": alpha, "seed": seed, "n_rods": info["n_rods"], **{r: res[r] for r in REGIONS},
                        "cv_e_all": res["fig"]["cv_e_all"]})
    return out


def old_measure(runs: Path) -> list[dict]:
    """Where the earlier measure's cv_e fell under compression: the lab run's own fields
    (``fields_press<E>.npz``: the text convention over the box inscribed in the cylinder, from the
    plate to the piston), cv_e over all its balls, over those below 0.7 of the piston's height,
    and over those within 2 R of the piston, with the mean e there over the mean e below."""
    from rodwarp.analysis import Fields

    out = []
    for folder in sorted(runs.glob("press_alpha*_seed*")):
        if not (folder / "summary.json").is_file():
            continue
        info = run_info(folder)
        for st in info["strains"]:
            if not st.get("fields") or not (folder / st["fields"]).is_file():
                continue
            f = Fields.load(folder / st["fields"])
            e = np.asarray(f.e)
            v = f.valid & np.isfinite(e)
            z = np.broadcast_to(np.asarray(f.z)[:, None, None], e.shape)
            top = float(st["piston_height"])
            below, near = v & (z <= 0.7 * top), v & (z > top - 2 * f.radius)
            cv = lambda m: float(e[m].std() / e[m].mean()) if m.any() and e[m].mean() > 0 else float("nan")  # noqa: E731
            out.append({"run": folder.name, "alpha": info["alpha"], "seed": info["seed"], "strain": float(st["strain"]),
                        "cv_e_box": cv(v), "cv_e_below": cv(below), "cv_e_top": cv(near),
                        "top_over_below_e": float(e[near].mean() / e[below].mean()) if near.any() else float("nan"),
                        "top_balls": int(near.sum()), "balls": int(v.sum())})
    return out


# ----------------------------------------------------------------------------- report

COLS = (("n", "n", 1), ("phi", "phi", 3), ("S", "S", 2), ("c", "c", 2), ("e", "e", 1),
        ("cv_e", "cv_e", 2), ("cv_n", "cv_n", 2), ("cv_e_pair", "cv e/pair", 2), ("e_pair_median", "e/pair", 3),
        ("e2_over_e", "e2/e", 2))


def _f(v, nd):
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "-"
    return f"{v:.{nd}f}"


def seed_mean(rows: list[dict], kind: str, alpha: int, strain: float, region: str) -> dict | None:
    sel = [r for r in rows if r["set"] == kind and r["alpha"] == alpha and abs(r["strain"] - strain) < 1e-9]
    if not sel:
        return None
    keys = sel[0][region].keys()
    out = {k: float(np.mean([r[region][k] for r in sel])) for k in keys}
    out["seeds"] = len(sel)
    out["spread"] = {k: float(np.ptp([r[region][k] for r in sel])) for k in ("cv_e", "e_pair_median", "n")}
    out["cv_e_min"] = float(min(r[region]["cv_e"] for r in sel))
    out["cv_e_max"] = float(max(r[region]["cv_e"] for r in sel))
    return out


def write_md(path: Path, rec: dict) -> None:
    rows, ct = rec["sim"], rec["ct"]
    L = ["# The fields of the lab's pressed packings against the authors' CT, like for like", "",
         f"Written by `scripts/ct_like_for_like.py` on {rec['date']} ({rec['machine']}; rodwarp "
         f"{rec['versions']['rodwarp']}, Warp {rec['versions']['warp']}). Command: `{rec['command']}`.", "",
         "Both sides: the authors' convention (docs/fields.md) for n, e, e2, S and c on their grid "
         f"(R = sqrt(d l), h = R / 2); the simulated rods resampled to edges of {rec['edge_d']:g} d; phi the CT's "
         "as published and the simulation's exact clipped volume; the region rule of "
         "`rodwarp.analysis.packing_regions` (each packing's own axis, radius and height from its n field; "
         "core r < 0.55 of its radius, 15-70% of its height; rim the rest of that band); e per rod pair = "
         "median over balls of e / (n (n - 1) / 2) (the authors' e counts every pair twice). The simulated "
         "packings: `rodwarp simulate --protocol lab`, steel, real gravity, the exact contact law (Signorini, "
         "Coulomb mu 0.2), rigid rods (the sag rule at alpha 38-100), seed means.", ""]
    L += ["## The packings", "", "| set | what it changes | alphas | rods | seeds |", "|---|---|---|---|---|"]
    for kind, what in SETS.items():
        sel = [r for r in rows if r["set"] == kind and r["strain"] == 0]
        if sel:
            al = sorted({r["alpha"] for r in sel})
            L.append(f"| {kind} | {what} | {', '.join(map(str, al))} | "
                     f"{', '.join(str(next(r['n_rods'] for r in sel if r['alpha'] == a)) for a in al)} | "
                     f"{', '.join(str(len({r['seed'] for r in sel if r['alpha'] == a})) for a in al)} |")
    L += ["", "Each packing's region geometry (m): radius, bottom and top of its body, at strain 0.", "",
          "| packing | radius | bottom | top | core balls | rim balls |", "|---|---|---|---|---|---|"]
    for a in ALPHAS:
        c = ct.get(f"{a}_0")
        if c:
            g = c["geometry"]
            L.append(f"| CT alpha {a} | {g['radius']:.4f} | {g['bottom']:.4f} | {g['top']:.4f} | {g['core_balls']} | "
                     f"{g['rim_balls']} |")
    for r in rows:
        if r["strain"] == 0 and r["seed"] == 0:
            g = r["geometry"]
            L.append(f"| {r['run']} | {g['radius']:.4f} | {g['bottom']:.4f} | {g['top']:.4f} | {g['core_balls']} | "
                     f"{g['rim_balls']} |")
    L += ["", "The authors' c rule, checked on the CT's own grid: mean c over the occupied balls is about "
          "V_cyl / (occupied balls h^3) whatever the contacts (`c_check`), against the published mean.", "",
          "| alpha | rule's mean c | published mean c |", "|---|---|---|"]
    for a in ALPHAS:
        c = ct.get(f"{a}_0", {}).get("c_check")
        if c:
            L.append(f"| {a} | {c['rule_mean_c']:.2f} | {c['published_mean_c']:.2f} |")
    for kind in SETS:
        if not any(r["set"] == kind for r in rows):
            continue
        L += ["", f"## CT against `{kind}` ({SETS[kind]})", "",
              "Each cell: CT / simulated (seed mean). e/pair: median over balls.", "",
              "| alpha | strain | region | " + " | ".join(c[1] for c in COLS) + " |",
              "|---|---|---|" + "---|" * len(COLS)]
        for a in ALPHAS:
            for s in STRAINS:
                for region in REGIONS:
                    sm = seed_mean(rows, kind, a, s, region)
                    c = ct.get(f"{a}_{s:g}")
                    if sm is None:
                        continue
                    cr = c[region] if c else {}
                    cells = [f"{_f(cr.get(k), nd)} / {_f(sm.get(k), nd)}" for k, _, nd in COLS]
                    L.append(f"| {a} | {s:g} | {region} | " + " | ".join(cells) + " |")
    ctl = rec.get("controls", {})
    if ctl.get("edges"):
        L += ["", "## The edge length (press, seed 0, strain 0, core)", "",
              "The authors' e depends on the centrelines' edge length; the CT's is not published. e2 / e "
              "grows with it and is the check.", "",
              "| alpha | edge (d) | n | e | cv_e | e/pair | e2/e | CT e2/e |", "|---|---|---|---|---|---|---|---|"]
        for r in ctl["edges"]:
            c = ct.get(f"{r['alpha']}_0", {}).get("core", {})
            k = r["core"]
            L.append(f"| {r['alpha']} | {r['edge_d']:g} | {k['n']:.1f} | {k['e']:.1f} | {k['cv_e']:.2f} | "
                     f"{k['e_pair_median']:.3f} | {k['e2_over_e']:.2f} | {_f(c.get('e2_over_e'), 2)} |")
    if ctl.get("noise"):
        L += ["", f"## Tracing noise (press, seed 0, strain 0, edges {rec['edge_d']:g} d)", "",
              "Interior vertices moved by a Gaussian of sigma per axis, in CT voxels (78.22 um): a crooked "
              "traced centreline, or a rod not quite straight.", "",
              "| alpha | sigma (voxels) | sigma (d) | core cv_e | core e/pair | rim cv_e | rim e/pair | core e2/e |",
              "|---|---|---|---|---|---|---|---|"]
        for r in ctl["noise"]:
            L.append(f"| {r['alpha']} | {r['noise_voxels']:g} | {r['noise_d']:.2f} | {r['core']['cv_e']:.2f} | "
                     f"{r['core']['e_pair_median']:.3f} | {r['rim']['cv_e']:.2f} | {r['rim']['e_pair_median']:.3f} | "
                     f"{r['core']['e2_over_e']:.2f} |")
    if ctl.get("bow"):
        L += ["", f"## Bent rods (press, seed 0, strain 0, edges {rec['edge_d']:g} d)", "",
              "Each rod bent into a half-sine bow of the given depth at mid-length, in a random direction across "
              "its axis: rods not quite straight.", "",
              "| alpha | bow (d) | core cv_e | core cv_n | core e/pair | rim cv_e |", "|---|---|---|---|---|---|"]
        for r in ctl["bow"]:
            L.append(f"| {r['alpha']} | {r['bow_d']:g} | {r['core']['cv_e']:.2f} | {r['core']['cv_n']:.2f} | "
                     f"{r['core']['e_pair_median']:.3f} | {r['rim']['cv_e']:.2f} |")
    if ctl.get("old_measure"):
        L += ["", "## The earlier measure's fall under compression (press, text convention)", "",
              "The lab run's own fields (`fields_press<E>.npz`: the box inscribed in the cylinder, from the plate to "
              "the piston), cv_e over all balls, over those below 0.7 of the piston's height, and over those "
              "within 2 R of the piston (with their mean e over the mean e below).", "",
              "| run | strain | cv_e box | cv_e below 0.7 H | cv_e top 2 R | top e / below e | top balls |",
              "|---|---|---|---|---|---|---|"]
        for r in ctl["old_measure"]:
            if r["strain"] in (0.0, 0.15):
                L.append(f"| {r['run']} | {r['strain']:g} | {r['cv_e_box']:.2f} | {r['cv_e_below']:.2f} | "
                         f"{r['cv_e_top']:.2f} | {r['top_over_below_e']:.2f} | {r['top_balls']} |")
    if ctl.get("structureless"):
        L += ["", "## A packing without structure (random sequential addition)", "",
              "The press set's rods placed uniformly and isotropically, without overlaps, in the same cylinder up "
              "to the poured packing's top (seed 0, strain 0), through the same fields and regions: the cv_e that "
              "finite balls give without any clumping.", "",
              "| alpha | seeds | rods | core n | core cv_e | rim cv_e | all balls cv_e | core e/pair |",
              "|---|---|---|---|---|---|---|---|"]
        for a in ALPHAS:
            sel = [r for r in ctl["structureless"] if r["alpha"] == a]
            if sel:
                m = lambda f: float(np.mean([f(r) for r in sel]))  # noqa: E731
                L.append(f"| {a} | {len(sel)} | {sel[0]['n_rods']} | {m(lambda r: r['core']['n']):.1f} | "
                         f"{m(lambda r: r['core']['cv_e']):.2f} (worst {max(r['core']['cv_e'] for r in sel):.2f}) | "
                         f"{m(lambda r: r['rim']['cv_e']):.2f} | {m(lambda r: r['cv_e_all']):.2f} | "
                         f"{m(lambda r: r['core']['e_pair_median']):.3f} |")
    path.write_text("\n".join(L) + "\n")


def write_figure(path: Path, rec: dict) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, ct = rec["sim"], rec["ct"]
    kinds = [k for k in SETS if any(r["set"] == k for r in rows)]
    fig, axes = plt.subplots(3, 4, figsize=(16, 10), sharex=True)
    styles = {"press": "o-", "press-frictionless": "s--", "press-ct": "^-.", "press-wide": "v:"}
    for j, a in enumerate(ALPHAS):
        for i, (key, label) in enumerate((("cv_e", "cv_e"), ("cv_n", "cv_n (rods per ball)"),
                                          ("e_pair_median", "e per rod pair (median)"))):
            ax = axes[i, j]
            for region, col in (("core", "C0"), ("rim", "C3")):
                xs = [s for s in STRAINS if f"{a}_{s:g}" in ct]
                ax.plot(xs, [ct[f"{a}_{s:g}"][region][key] for s in xs], "k" + ("-" if region == "core" else "--"),
                        lw=2, label=f"CT {region}")
                for kind in kinds:
                    pts = [(s, seed_mean(rows, kind, a, s, region)) for s in STRAINS]
                    pts = [(s, m[key]) for s, m in pts if m]
                    if pts:
                        ax.plot(*zip(*pts), styles[kind], color=col, ms=4, alpha=0.8,
                                label=f"{kind} {region}")
            ax.set_title(f"alpha {a}")
            if j == 0:
                ax.set_ylabel(label)
            if i == 2:
                ax.set_xlabel("strain")
    axes[0, 0].legend(fontsize=6)
    fig.suptitle("Pressed packings against the authors' CT: authors' convention, each packing's core and rim")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


#: the packings of the CT's size: its container at l = 50 mm, twice the press set's pile at alpha 38
CT_SIZE = ("press-ct", "press-wide")


def _fig_rows(rec: dict) -> dict:
    """alpha -> {"ct": fig data, "sim": [the press set's seeds], "big": [CT-size packings]} at strain 0."""
    out = {}
    for a in ALPHAS:
        c = rec["ct"].get(f"{a}_0")
        at0 = [r for r in rec["sim"] if r["alpha"] == a and r["strain"] == 0]
        sims = [r["fig"] for r in at0 if r["set"] == "press"]
        if c and sims:
            out[a] = {"ct": c["fig"], "sim": sims, "big": [r["fig"] for r in at0 if r["set"] in CT_SIZE],
                      "big_set": sorted({r["set"] for r in at0 if r["set"] in CT_SIZE}),
                      "length_m": next(r["length_m"] for r in at0)}
    return out


def write_fig23(out: Path, rec: dict) -> None:
    """Fig. 2 (p(S), p(c)) and Fig. 3F-M (tangles, percolation, z-profiles) of the CT and of the
    press set's poured packings (strain 0), both in the authors' convention; fig23.md and .json."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = _fig_rows(rec)
    if not data:
        return
    colours = dict(zip(ALPHAS, ("tab:blue", "tab:orange", "tab:green", "tab:red")))
    sc = 0.5 * (S_BINS[1:] + S_BINS[:-1])
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.8))
    for a, d in data.items():
        axes[0].plot(sc, d["ct"]["p_S"], "-", color=colours[a], label=f"alpha {a} CT")
        axes[0].plot(sc, np.mean([s["p_S"] for s in d["sim"]], axis=0), "--", color=colours[a], label=f"alpha {a} sim")
        axes[1].plot(d["ct"]["q_c"], C_QUANTILES, "-", color=colours[a])
        axes[1].plot(np.mean([s["q_c"] for s in d["sim"]], axis=0), C_QUANTILES, "--", color=colours[a])
    axes[0].set_xlabel("S (authors': eigenvalue of largest magnitude)")
    axes[1].set_xlabel("c / mean c")
    axes[1].set_xlim(0, 4)
    for ax, t in zip(axes, ("p(S)", "P(c / mean c <= x)")):
        ax.set_title(f"{t}: CT (solid), press set (dashed), strain 0, occupied balls", fontsize=8)
    axes[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(out / "fig2_pS_pc.png", dpi=120)
    plt.close(fig)

    al = sorted(data)
    fig, axes = plt.subplots(1, 3, figsize=(11, 3.4))
    for src, marker in (("ct", "o"), ("sim", "s"), ("big", "^")):
        aa = [a for a in al if (data[a][src] if src != "ct" else True)]
        if not aa:
            continue
        get = (lambda d: [d["ct"]]) if src == "ct" else (lambda d, src=src: d[src])
        n_t = [np.mean([1e4 * f["n_tangles"] / f["balls"] for f in get(data[a])]) for a in aa]
        ext = [np.mean([max((f["largest_xi_over_L"] or {"x": 0}).values()) for f in get(data[a])]) for a in aa]
        perc = [np.mean([f["percolates"] for f in get(data[a])]) for a in aa]
        lab = {"ct": "CT", "sim": "press set (seed mean)", "big": "CT-size pile (press-ct, press-wide)"}[src]
        for ax, v in zip(axes, (n_t, ext, perc)):
            ax.plot(aa, v, marker, ls="-", label=lab)
    for ax, t in zip(axes, ("tangles (e > e_lb, 26-connected) per 10^4 occupied balls", "largest tangle: max xi / L",
                            "largest tangle percolates (share)")):
        ax.set_xlabel("alpha")
        ax.set_title(t, fontsize=9)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "fig3_tangles.png", dpi=120)
    plt.close(fig)

    fig, axes = plt.subplots(1, 4, figsize=(14, 3.6))
    for ax, name, lab in zip(axes, ("phi", "S", "c", "e"), ("phi", "S", "c / mean c", "e")):
        for a, d in data.items():
            zl = np.asarray(d["ct"]["z"]) / d["length_m"]
            ax.plot(zl, d["ct"]["profiles"][name], "-", color=colours[a], label=f"alpha {a} CT")
            s0 = (d["big"] or d["sim"])[0]  # the CT-size pile where there is one: height matters here
            ax.plot(np.asarray(s0["z"]) / d["length_m"], s0["profiles"][name], "--", color=colours[a],
                    label=f"alpha {a} sim ({d['big_set'][0] if d['big'] else 'press'})")
        ax.axvline(0.5, color="grey", lw=0.8)
        ax.set_xlabel("z / l")
        ax.set_title(f"{lab}(z), occupied balls", fontsize=9)
    axes[0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(out / "fig3_zprofiles.png", dpi=120)
    plt.close(fig)

    L = ["# Fig. 2-3: the lab's poured packings beside the CT, like for like", "",
         f"Written by `scripts/ct_like_for_like.py` on {rec['date']} ({rec['machine']}). Both sides in the "
         f"authors' convention (the simulated rods resampled to edges of {rec['edge_d']:g} d), over every "
         "occupied ball (n > 0) as the authors' statistics count them. Simulated: the lab's packings at "
         "strain 0 (poured into the cylinder, the piston resting on them; docs/experiments.md): the `press` set "
         "(Rc = l, filled to 1 l, seed means) and the CT-size piles (`press-ct`: the CT's 150 mm container "
         "filled to 100 mm; `press-wide`: alpha 38, Rc = 2 l, filled to 2 l). p(S) and c's distribution from the "
         "press set, the z-profiles from the CT-size pile where there is one. c is shown over its packing's "
         "mean: the authors' normalisation of c does not carry over (ct_like_for_like.md).", "",
         "| alpha | packing | median S | mean e | cv_e | e_lb | tangles | per 10^4 balls | balls | largest tangle "
         "max xi/L | percolates |",
         "|---|---|---|---|---|---|---|---|---|---|---|"]
    for a in al:
        for src in ("ct", "sim", "big"):
            fs = [data[a]["ct"]] if src == "ct" else data[a][src]
            if not fs:
                continue
            m = lambda k: float(np.mean([f[k] for f in fs]))  # noqa: E731
            ext = np.mean([max((f["largest_xi_over_L"] or {"x": 0}).values()) for f in fs])
            seeds = f"{len(fs)} seed{'s' if len(fs) > 1 else ''}"
            name = {"ct": "CT, strain 0", "sim": f"press ({seeds})",
                    "big": f"{data[a]['big_set'][0] if data[a]['big_set'] else ''} ({seeds})"}[src]
            L.append(f"| {a} | {name} | "
                     f"{m('median_S'):.2f} | {m('mean_e_all'):.1f} | {m('cv_e_all'):.2f} | {m('e_lb'):.0f} | "
                     f"{m('n_tangles'):.1f} | {1e4 * m('n_tangles') / m('balls'):.1f} | {m('balls'):.0f} | {ext:.2f} | "
                     f"{m('percolates'):.2f} |")
    L += ["", "Figures: [fig2_pS_pc.png](fig2_pS_pc.png), [fig3_tangles.png](fig3_tangles.png), "
          "[fig3_zprofiles.png](fig3_zprofiles.png)."]
    (out / "fig23.md").write_text("\n".join(L) + "\n")
    (out / "fig23.json").write_text(json.dumps({"command": rec["command"], "date": rec["date"],
                                                "machine": rec["machine"], "versions": rec["versions"],
                                                "edge_d": rec["edge_d"], "alphas": data}, indent=1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", required=True, help="folder of scripts/lab_experiments.py runs")
    ap.add_argument("--paper-fields", required=True, help="folder of the authors' fields (alpha*_epsilon*.npz)")
    ap.add_argument("--edge", type=float, default=4.0, help="simulated edge length, rod diameters (default 4)")
    ap.add_argument("--cache", default=None, help="cache folder (default RUNS/../ct_like_for_like_cache)")
    ap.add_argument("--no-controls", action="store_true", help="leave out the edge and noise controls")
    ap.add_argument("--structureless", default="", help="alphas (e.g. 38,100) of the random-sequential-addition "
                    "control (minutes each: the placement nears jamming)")
    ap.add_argument("--structureless-seeds", default="0,1,2", help="its seeds (default 0,1,2)")
    ap.add_argument("--out", default=str(OUT), help="results folder (default benchmarks/results)")
    args = ap.parse_args(argv)
    runs, data = Path(args.runs), Path(args.paper_fields)
    for p, what in ((runs, "--runs"), (data, "--paper-fields")):
        if not p.is_dir():
            print(f"error: {what} {p} is not a folder; give an existing one", file=sys.stderr)
            return 2
    if not (args.edge > 0):
        print(f"error: --edge must be > 0 rod diameters, got {args.edge}", file=sys.stderr)
        return 2
    cache = Path(args.cache) if args.cache else runs.parent / "ct_like_for_like_cache"
    log = lambda m: print(f"{datetime.now(timezone.utc):%H:%M:%S} {m}", file=sys.stderr, flush=True)  # noqa: E731
    import rodwarp
    import warp as wp

    sys.path.insert(0, str(ROOT))
    from benchmarks.common import cpu_model

    ct = {}
    for a in ALPHAS:
        for s in STRAINS:
            f = ct_fields(data, a, s)
            if f is not None:
                ct[f"{a}_{s:g}"] = regional(f)
                ct[f"{a}_{s:g}"]["c_check"] = c_check(f, ct[f"{a}_{s:g}"]["geometry"])
    sim = analyse_runs(runs, cache, args.edge, log)
    given = list(argv if argv is not None else sys.argv[1:])
    # the data folder by its name: where it lies on this machine is not the record's
    shown = [Path(a).name if i and given[i - 1] == "--paper-fields" else a for i, a in enumerate(given)]
    rec = {"command": "python scripts/ct_like_for_like.py " + " ".join(shown),
           "date": f"{datetime.now(timezone.utc):%Y-%m-%d}", "machine": f"{cpu_model()}, {os.cpu_count()} cores", "versions": {"rodwarp": rodwarp.__version__, "warp": wp.__version__,
                                                                "numpy": np.__version__},
           "edge_d": args.edge, "ct": ct, "sim": sim,
           "controls": {} if args.no_controls else controls(runs, cache, args.edge, log)}
    rec["controls"]["old_measure"] = old_measure(runs)
    if args.structureless:
        rec["controls"]["structureless"] = structureless(
            runs, cache, args.edge, [int(a) for a in args.structureless.split(",")],
            [int(v) for v in args.structureless_seeds.split(",")], log)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "ct_like_for_like.json").write_text(json.dumps(rec, indent=1))
    write_md(out / "ct_like_for_like.md", rec)
    write_figure(out / "ct_like_for_like.png", rec)
    write_fig23(out, rec)
    print(f"wrote {out / 'ct_like_for_like.md'} ({len(sim)} simulated packings)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
