"""Contact search as the rod count grows: Warp hash grid against all pairs and scipy cKDTree.

Configuration: settled, contact-rich piles of N = 100 k steel rods (alpha = 100, 10 vertices),
made by placing k copies of one settled 100-rod pile side by side
(:func:`benchmarks.common.settled_tile`), so every N has the same local structure.
A *contact* is a segment pair (sa < sb, not adjacent on one rod) whose capsule gap at the
current positions is below ``model.contact_distance`` (d / 10).

Methods, all on the same positions:

* **rodwarp** (Warp ``HashGrid``): one ``solver.step`` with ``solver.reset_timings()``; the
  figure is the ``broadphase + narrowphase`` stage time: midpoints into the hash grid, the
  Verlet candidate list (exact capsule filter at margin + skin) and the narrowphase over it
  (exact gaps, radix sort, warm-start lookup).  *rebuild*: the pair list is rebuilt from
  scratch in the timed step (forced through ``solver.invalidate_pairs()``; a fresh
  solver per repeat when that hook is gone); *reuse*: the list is still valid (typical step).
  Rodwarp's contacts are the step's contacts with gap < contact distance.
* **cKDTree**: ``scipy.spatial.cKDTree`` on segment midpoints, ``query_pairs`` with rodwarp's
  own query radius (h_max + 2 r_max + margin + skin), then exact gaps with
  ``rodwarp.rodset.segment_distance`` on the candidates; also with the smallest radius
  that still finds every contact (h_max + 2 r_max + contact distance), "cKDTree (tight)".
* **all pairs**: exact gaps of every segment pair in NumPy (``segment_distance``, vectorised
  in chunks); skipped where its predicted time exceeds the limit (recorded as skipped).

All methods must return the same set of contacts; disagreements are recorded (pairs within
1e-9 m of the threshold count as ties, not errors).
"""

from __future__ import annotations

import math
import time

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, fmt_spread, log

NAME = "broadphase"
TITLE = "Contact search vs rod count: Warp hash grid, all pairs, scipy cKDTree"
LABELS = {"all_pairs": "all pairs", "ckdtree": "cKDTree", "ckdtree_tight": "cKDTree (tight)", "rodwarp": "rodwarp"}
TIE = 1e-9  # m: gaps this close to the contact distance may fall either side with rounding


def _segments(model, x):
    sv = model.seg_vertex_np
    p0 = x[sv]
    p1 = x[sv + 1]
    rod = model.vertex_rod_np[sv]
    return p0, p1, rod, sv


def _exclude(model, i, j):
    """Mask of pairs to keep: drop adjacent segments of one rod (as the engine does)."""
    sv = model.seg_vertex_np
    rod = model.vertex_rod_np[sv]
    va, vb = sv[i], sv[j]
    adjacent = (rod[i] == rod[j]) & ((vb == va + 1) | (va == vb + 1))
    return ~adjacent


def _gaps(model, x, i, j, chunk: int = 1 << 18):
    from rodwarp.rodset import segment_distance

    sv = model.seg_vertex_np
    r = model.radius_np[model.vertex_rod_np[sv]]
    out = np.empty(len(i))
    for s in range(0, len(i), chunk):
        a, b = i[s:s + chunk], j[s:s + chunk]
        out[s:s + chunk] = segment_distance(x[sv[a]], x[sv[a] + 1], x[sv[b]], x[sv[b] + 1]) - r[a] - r[b]
    return out


def ckdtree_contacts(model, x, radius: float):
    """(pairs (P, 2) with i < j, gaps, candidate count) through a cKDTree on midpoints."""
    from scipy.spatial import cKDTree

    sv = model.seg_vertex_np
    mid = 0.5 * (x[sv] + x[sv + 1])
    tree = cKDTree(mid)
    cand = tree.query_pairs(radius, output_type="ndarray")
    n_cand = len(cand)
    i, j = cand[:, 0], cand[:, 1]
    swap = i > j
    i, j = np.where(swap, j, i), np.where(swap, i, j)
    keep = _exclude(model, i, j)
    i, j = i[keep], j[keep]
    g = _gaps(model, x, i, j)
    hit = g < model.contact_distance
    return np.stack([i[hit], j[hit]], axis=1), g[hit], n_cand


def all_pairs_contacts(model, x, chunk: int = 1 << 18):
    """Exact gap of every segment pair (upper triangle), in row blocks; returns (pairs, gaps)."""
    from rodwarp.rodset import segment_distance

    sv = model.seg_vertex_np
    S = len(sv)
    p0, p1 = x[sv], x[sv + 1]
    r = model.radius_np[model.vertex_rod_np[sv]]
    cd = model.contact_distance
    found_i, found_j, found_g = [], [], []
    i0 = 0
    while i0 < S - 1:
        rows = max(1, min(S - 1 - i0, chunk // max(S - i0, 1)))
        i1 = i0 + rows
        ii = np.arange(i0, i1)
        jj = np.arange(i0 + 1, S)
        d = segment_distance(p0[ii, None], p1[ii, None], p0[None, jj], p1[None, jj])
        g = d - r[ii, None] - r[None, jj]
        mask = (jj[None, :] > ii[:, None]) & (g < cd)
        a, b = np.nonzero(mask)
        if len(a):
            ia, jb = ii[a], jj[b]
            keep = _exclude(model, ia, jb)
            found_i.append(ia[keep])
            found_j.append(jb[keep])
            found_g.append(g[a, b][keep])
        i0 = i1
    if not found_i:
        return np.zeros((0, 2), int), np.zeros(0)
    return np.stack([np.concatenate(found_i), np.concatenate(found_j)], axis=1), np.concatenate(found_g)


def _calibrate_all_pairs(model, x) -> float:
    """Pairs per second of the all-pairs kernel (a small block, best of 3)."""
    from rodwarp.rodset import segment_distance

    sv = model.seg_vertex_np
    n = min(len(sv), 400)
    ii = np.arange(n)
    best = math.inf
    for _ in range(3):
        t = time.perf_counter()
        segment_distance(x[sv[ii], None], x[sv[ii] + 1, None], x[None, sv[ii]], x[None, sv[ii] + 1])
        best = min(best, time.perf_counter() - t)
    return n * n / best


def _compare(ref_pairs, ref_gaps, pairs, gaps, cd) -> dict:
    def as_dict(p, g):
        return {(int(a), int(b)): float(x) for (a, b), x in zip(p, g)}

    A = as_dict(ref_pairs, ref_gaps)
    B = as_dict(pairs, gaps)
    only_a = set(A) - set(B)
    only_b = set(B) - set(A)
    ties = [k for k in only_a if abs(A[k] - cd) <= TIE] + [k for k in only_b if abs(B[k] - cd) <= TIE]
    real = [k for k in only_a | only_b if k not in set(ties)]
    common_keys = set(A) & set(B)
    gap_err = max((abs(A[k] - B[k]) for k in common_keys), default=0.0)
    worst = sorted(real, key=lambda k: abs((A.get(k) if k in A else B[k]) - cd), reverse=True)[:5]
    return {"n_ref": len(A), "n": len(B), "only_in_reference": len(only_a), "only_in_method": len(only_b),
            "ties_at_threshold": len(ties), "disagreements": len(real), "agree": len(real) == 0,
            "max_gap_difference_m": gap_err,
            "examples": [{"pair": list(k), "gap_reference": A.get(k), "gap_method": B.get(k)} for k in worst]}


def _point(n_tiles: int, quick: bool, device: str, limit_s: float, rate: list) -> dict:
    from rodwarp.sim.state import State
    from rodwarp.sim.solver import RodSolver

    repeats = common.n_repeats(quick)
    tile = common.settled_tile(device)
    model = common.tiled_model(tile, n_tiles, device=device)
    N, S = model.n_rods, model.n_segments
    solver = RodSolver(model)
    dt = solver.default_dt()
    A = model.state()
    B = State(model)
    solver.step(A, B, dt=dt)  # untimed: allocations, first-step energy evaluation
    x = A.positions()
    cd = model.contact_distance

    hook = hasattr(solver, "invalidate_pairs")

    def timed_step(rebuild: bool):
        s = solver
        if rebuild:
            if hook:
                s.invalidate_pairs()
            else:
                s = RodSolver(model)
        s.reset_timings()
        common.sync(device)
        t = time.perf_counter()
        s.step(A, B, dt=dt)
        common.sync(device)
        wall = time.perf_counter() - t
        tm = s.timings
        s.timings = None
        return tm.get("broadphase", 0.0) + tm.get("narrowphase", 0.0), tm.get("broadphase", 0.0), wall

    # the pair list's margin and the query radius rodwarp uses (private; recomputed when absent)
    timed_step(True)
    margin = getattr(solver, "_pairs_margin", None)
    hmax = float(model.rest_length_np.max())
    rmax = float(model.radius_np.max())
    if not margin:
        margin = cd + 2.0 * float(np.linalg.norm(model.gravity)) * dt * dt + solver.skin
    query = (hmax + 2.0 * rmax + margin) * 1.0001 + 1e-6
    tight = (hmax + 2.0 * rmax + cd) * 1.0001 + 1e-6

    n_pairs_total = S * (S - 1) // 2
    if not rate:
        rate.append(_calibrate_all_pairs(model, x))
    predicted = n_pairs_total / rate[0]
    ap = {"pairs_evaluated": n_pairs_total, "predicted_s": predicted, "pairs_per_s_calibrated": rate[0]}
    run_ap = predicted <= limit_s
    if not run_ap:
        ap.update({"skipped": True, "reason": f"predicted {predicted:.0f} s > limit {limit_s:.0f} s per run"})

    out = {}
    samples = {k: [] for k in ("rebuild", "rebuild_bp", "rebuild_step", "reuse", "reuse_bp", "reuse_step",
                               "ckdtree", "ckdtree_tight", "all_pairs")}

    def timed(key, fn):
        t = time.perf_counter()
        out[key] = fn()
        samples[key].append(time.perf_counter() - t)

    # warm-up of the peers (imports, first-call allocations)
    ckdtree_contacts(model, x, tight)
    # interleaved rounds: every method once per round, so drifts in machine load hit all alike
    for _ in range(repeats):
        for mode in ("rebuild", "reuse"):
            a_, b_, c_ = timed_step(mode == "rebuild")
            samples[mode].append(a_)
            samples[mode + "_bp"].append(b_)
            samples[mode + "_step"].append(c_)
        timed("ckdtree", lambda: ckdtree_contacts(model, x, query))
        timed("ckdtree_tight", lambda: ckdtree_contacts(model, x, tight))
        if run_ap:
            timed("all_pairs", lambda: all_pairs_contacts(model, x))
    res = {mode: {"search_s": common.spread(samples[mode]), "broadphase_s": common.spread(samples[mode + "_bp"]),
                  "step_s": common.spread(samples[mode + "_step"])} for mode in ("rebuild", "reuse")}
    builds_ok = (not hook) or solver.pair_builds >= repeats
    last = solver.default_contacts.last
    n = last.count
    seg = last.seg.numpy()[:n].astype(np.int64)
    gap = last.gap.numpy()[:n]
    keep = gap < cd
    rw_pairs, rw_gaps = seg[keep], gap[keep]

    kd = {}
    for label, radius in (("ckdtree", query), ("ckdtree_tight", tight)):
        pairs, gaps, ncand = out[label]
        kd[label] = {"time_s": common.spread(samples[label]), "query_radius_m": radius, "candidates": int(ncand),
                     "_pairs": (pairs, gaps)}
    ap_pairs = None
    if run_ap:
        ap["time_s"] = common.spread(samples["all_pairs"])
        ap["skipped"] = False
        ap_pairs = out["all_pairs"]
        rate[0] = n_pairs_total / ap["time_s"]["median"]  # refine the prediction for the next N

    # agreement: all pairs (exact, when run) is the reference, else cKDTree
    ref_label = "all_pairs" if ap_pairs is not None else "ckdtree"
    ref = ap_pairs if ap_pairs is not None else kd["ckdtree"]["_pairs"]
    agreement = {"reference": ref_label,
                 "rodwarp": _compare(ref[0], ref[1], rw_pairs, rw_gaps, cd),
                 "ckdtree": _compare(ref[0], ref[1], *kd["ckdtree"]["_pairs"], cd),
                 "ckdtree_tight": _compare(ref[0], ref[1], *kd["ckdtree_tight"]["_pairs"], cd)}
    for v in kd.values():
        v.pop("_pairs")
    ok = all(a["agree"] for k, a in agreement.items() if k != "reference")
    rw = res["rebuild"]["search_s"]["median"]
    log(f"broadphase N={N} (S={S}): rodwarp rebuild {fmt(rw * 1e3)} ms, reuse "
        f"{fmt(res['reuse']['search_s']['median'] * 1e3)} ms, cKDTree {fmt(kd['ckdtree']['time_s']['median'] * 1e3)} ms, "
        f"all pairs {'skipped' if ap['skipped'] else fmt(ap['time_s']['median'] * 1e3) + ' ms'}; "
        f"{len(rw_pairs)} contacts, agree={ok}")
    return {
        "n_rods": N, "n_segments": S, "n_tiles": n_tiles, "dt_s": dt, "contact_distance_m": cd,
        "rodwarp_query_radius_m": query, "tight_query_radius_m": tight, "verlet_margin_m": margin,
        "rodwarp": res, "rodwarp_forced_rebuilds": builds_ok, "rodwarp_contacts": int(len(rw_pairs)),
        "rodwarp_step_contacts_speculative": int(n),
        "ckdtree": kd["ckdtree"], "ckdtree_tight": kd["ckdtree_tight"], "all_pairs": ap,
        "agreement": agreement, "all_agree": ok,
    }


def run(quick: bool, device: str) -> dict:
    sizes = [100, 300, 1000, 3000] if quick else [100, 300, 1000, 3000, 10000, 30000]
    limit = 12.0 if quick else 30.0
    tile = common.settled_tile(device)
    rate: list = []
    points = [_point(n // 100, quick, device, limit, rate) for n in sizes]

    def slope(key_fn):
        xs, ys = [], []
        for p in points:
            y = key_fn(p)
            if y is not None:
                xs.append(p["n_rods"])
                ys.append(y)
        return {"all": common.loglog_slope(xs, ys),
                "N>=1000": common.loglog_slope([x for x in xs if x >= 1000], [y for x, y in zip(xs, ys) if x >= 1000])}

    slopes = {
        "rodwarp_rebuild": slope(lambda p: p["rodwarp"]["rebuild"]["search_s"]["median"]),
        "rodwarp_reuse": slope(lambda p: p["rodwarp"]["reuse"]["search_s"]["median"]),
        "ckdtree": slope(lambda p: p["ckdtree"]["time_s"]["median"]),
        "ckdtree_tight": slope(lambda p: p["ckdtree_tight"]["time_s"]["median"]),
        "all_pairs": slope(lambda p: None if p["all_pairs"]["skipped"] else p["all_pairs"]["time_s"]["median"]),
    }
    problems = []
    for p in points:
        for k, a in p["agreement"].items():
            if k != "reference" and not a["agree"]:
                problems.append(f"N={p['n_rods']}: {k} finds a different contact set from {p['agreement']['reference']} "
                                f"({a['only_in_reference']} only in reference, {a['only_in_method']} only in {k}, "
                                f"{a['ties_at_threshold']} threshold ties); examples {a['examples'][:2]}")
        if not p["rodwarp_forced_rebuilds"]:
            problems.append(f"N={p['n_rods']}: forcing a pair-list rebuild did not register (pair_builds)")
    return {
        "name": NAME, "title": TITLE,
        "settings": {"sizes": sizes, "all_pairs_limit_s": limit, "tile": common.tile_description(tile),
                     "layout": "k copies of the settled 100-rod tile on a near-square grid, 0.05 m apart",
                     "contact": "segment pair (sa < sb, not adjacent on one rod) with capsule gap < contact distance (d/10)",
                     "rodwarp_figure": "broadphase + narrowphase stage seconds of one profiled step",
                     "peer_figure": "wall seconds: cKDTree build + query_pairs + exact gaps; all pairs: exact gaps"},
        "points": points,
        "slopes": slopes,
        "problems": problems,
    }


# ----------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------

def summary(rec: dict) -> list[dict]:
    rows = []
    for p in rec["points"]:
        rw = p["rodwarp"]["rebuild"]["search_s"]
        reuse = p["rodwarp"]["reuse"]["search_s"]
        base = f"N={p['n_rods']} ({p['n_segments']} segments, {p['rodwarp_contacts']} contacts)"
        rw_txt = f"rebuild {fmt_spread(rw, 1e3, 'ms')}; reuse {fmt_spread(reuse, 1e3, 'ms')}"
        kd = p["ckdtree"]["time_s"]
        rows.append({"benchmark": f"{base}: vs cKDTree (same radius)", "rodwarp": rw_txt,
                     "peer": f"cKDTree {fmt_spread(kd, 1e3, 'ms')}", "ratio": kd["median"] / rw["median"]})
        ap = p["all_pairs"]
        if ap["skipped"]:
            rows.append({"benchmark": f"{base}: vs all pairs", "rodwarp": rw_txt,
                         "peer": f"all pairs skipped ({ap['reason']})",
                         "ratio": f"~{ap['predicted_s'] / rw['median']:.3g}x (predicted)"})
        else:
            rows.append({"benchmark": f"{base}: vs all pairs", "rodwarp": rw_txt,
                         "peer": f"all pairs {fmt_spread(ap['time_s'], 1e3, 'ms')}",
                         "ratio": ap["time_s"]["median"] / rw["median"]})
    sl = rec["slopes"]
    rows.append({"benchmark": "log-log slope of time vs N (all sizes / N>=1000)",
                 "rodwarp": f"rebuild {fmt(sl['rodwarp_rebuild']['all'])} / {fmt(sl['rodwarp_rebuild']['N>=1000'])}; "
                            f"reuse {fmt(sl['rodwarp_reuse']['all'])} / {fmt(sl['rodwarp_reuse']['N>=1000'])}",
                 "peer": f"cKDTree {fmt(sl['ckdtree']['all'])} / {fmt(sl['ckdtree']['N>=1000'])}; all pairs "
                         f"{fmt(sl['all_pairs']['all'])}",
                 "ratio": None})
    agree = all(p["all_agree"] for p in rec["points"])
    refs = {}
    for p in rec["points"]:
        refs.setdefault(p["agreement"]["reference"], []).append(str(p["n_rods"]))
    n_c = ", ".join(f"N={p['n_rods']}: {p['rodwarp_contacts']}" for p in rec["points"])
    rows.append({"benchmark": "same contact set from all methods (gap < d/10)",
                 "rodwarp": ("yes, at every N" if agree else "NO (see problems)") + f"; contacts {n_c}",
                 "peer": "reference: " + "; ".join(f"{LABELS.get(k, k)} at N = {', '.join(v)}" for k, v in refs.items()),
                 "ratio": None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()
    pts = rec["points"]
    N = np.array([p["n_rods"] for p in pts], float)
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5))

    def series(get):
        med, lo, hi = [], [], []
        for p in pts:
            s = get(p)
            med.append(np.nan if s is None else s["median"])
            lo.append(np.nan if s is None else s["min"])
            hi.append(np.nan if s is None else s["max"])
        med, lo, hi = (np.array(v) * 1e3 for v in (med, lo, hi))
        return med, lo, hi

    sl = rec["slopes"]
    lines = [
        ("rodwarp hash grid, list rebuilt", lambda p: p["rodwarp"]["rebuild"]["search_s"], dict(color="C0", marker="o", lw=2.2), "rodwarp_rebuild"),
        ("rodwarp hash grid, Verlet list reused", lambda p: p["rodwarp"]["reuse"]["search_s"], dict(color="C0", marker="o", ls=":", mfc="none"), "rodwarp_reuse"),
        ("scipy cKDTree, same radius", lambda p: p["ckdtree"]["time_s"], dict(color="C1", marker="s"), "ckdtree"),
        ("scipy cKDTree, tight radius", lambda p: p["ckdtree_tight"]["time_s"], dict(color="C1", marker="s", ls="--", mfc="none"), "ckdtree_tight"),
        ("all pairs (NumPy)", lambda p: None if p["all_pairs"]["skipped"] else p["all_pairs"]["time_s"], dict(color="C3", marker="^"), "all_pairs"),
    ]
    for label, get, style, key in lines:
        med, lo, hi = series(get)
        s = sl[key]["all"]
        ax.errorbar(N, med, yerr=[med - lo, hi - med], capsize=3, label=f"{label} (slope {fmt(s, 2)})", **style)
    skipped = [(p["n_rods"], p["all_pairs"]["predicted_s"] * 1e3) for p in pts if p["all_pairs"]["skipped"]]
    if skipped:
        ax.plot(*zip(*skipped), "^", color="C3", mfc="none", ls="none", label="all pairs, skipped (predicted)")
    # guide slopes
    x0 = N[0]
    y0 = series(lines[0][1])[0][0]
    for k, txt in ((1, "∝ N"), (2, "∝ N²")):
        ax.plot(N, y0 * (N / x0) ** k, color="0.6", lw=0.8, ls="-.")
        ax.annotate(txt, (N[-1], y0 * (N[-1] / x0) ** k), fontsize=8, color="0.4")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("rods N (9 segments each)")
    ax.set_ylabel("contact search time (ms; median, bars min–max)")
    ax.set_title("Contact search time vs N (settled piles)", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7.5, loc="upper left")

    rw = series(lines[0][1])[0]
    kd = series(lines[2][1])[0]
    ap = series(lines[4][1])[0]
    ax2.plot(N, kd / rw, "s-", color="C1", label="cKDTree (same radius) / rodwarp rebuild")
    ax2.plot(N, series(lines[3][1])[0] / rw, "s--", color="C1", mfc="none", label="cKDTree (tight) / rodwarp rebuild")
    ax2.plot(N, ap / rw, "^-", color="C3", label="all pairs / rodwarp rebuild")
    ax2.plot(N, kd / series(lines[1][1])[0], "o:", color="C0", mfc="none", label="cKDTree (same radius) / rodwarp reuse")
    ax2.axhline(1.0, color="k", lw=0.8)
    ax2.set_xscale("log")
    ax2.set_yscale("log")
    ax2.set_xlabel("rods N")
    ax2.set_ylabel("peer time / rodwarp time (>1: rodwarp faster)")
    ax2.set_title("Speed ratio (same run, same positions)", fontsize=10)
    ax2.grid(True, which="both", alpha=0.3)
    ax2.legend(fontsize=7.5)
    fig.suptitle(f"Contact search, {common.short_device(rec)}", fontsize=11)
    fig.tight_layout()
    f = common.save_figure(fig, outdir / f"{NAME}_scaling.png")
    last = pts[-1]
    largest_ap = [p for p in pts if not p["all_pairs"]["skipped"]]
    agree = all(p["all_agree"] for p in pts)
    reading = (f"Left: time to find all contacts against N on log-log axes, settled piles of tiled 100-rod piles; "
               f"fitted slopes: rodwarp rebuild {fmt(sl['rodwarp_rebuild']['all'], 2)} "
               f"({fmt(sl['rodwarp_rebuild']['N>=1000'], 2)} for N >= 1000), cKDTree {fmt(sl['ckdtree']['all'], 2)}, "
               f"all pairs {fmt(sl['all_pairs']['all'], 2)} (quadratic, as expected). Right: peer time over rodwarp "
               f"time. At N={last['n_rods']} rodwarp rebuilds its list and finds the contacts in "
               f"{fmt(last['rodwarp']['rebuild']['search_s']['median'] * 1e3)} ms, "
               f"{fmt(last['ckdtree']['time_s']['median'] / last['rodwarp']['rebuild']['search_s']['median'])}x faster than "
               f"cKDTree with the same radius; a step that reuses the Verlet list spends "
               f"{fmt(last['rodwarp']['reuse']['search_s']['median'] * 1e3)} ms. "
               + (f"All pairs was run up to N={largest_ap[-1]['n_rods']} "
                  f"({fmt(largest_ap[-1]['all_pairs']['time_s']['median'] / largest_ap[-1]['rodwarp']['rebuild']['search_s']['median'])}x "
                  f"slower than rodwarp there) and skipped above (hollow triangles: predicted time). " if largest_ap else "")
               + ("All methods found the same contact set at every N." if agree else
                  "The methods did NOT all find the same contact set: see the problems list."))
    return [{"file": f, "title": "Contact search scaling", "reading": reading}]
