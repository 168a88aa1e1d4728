"""Independent ACN and linking-number implementations against ``rodwarp.analysis``, same run.

Curve pairs (vertices in arbitrary units, both curves with n segments):

* ``hopf``: two unit circles in perpendicular planes, each through the other's centre
  (linking number +-1), turned by a fixed generic rotation; closed.
* ``torus T(2,2k)``, k = 2 and 5: the two components (theta = s, phi = k s) and
  (theta = s, phi = k s + pi) on a torus R = 2, r = 1 (linking number +-k); closed.
* ``random closed``: two closed random polygons (Gaussian steps made to close, a Brownian
  bridge), scaled to unit RMS radius, centres 0.3 apart (entangled; integer linking number).
* ``random open``: two open random walks (Gaussian steps), unit RMS radius, starts 0.3 apart
  (real-valued Gauss linking integral).

Sizes n = 100, 300, 1000, 2000 segments per curve (quick) or 100 ... 3000 (full).

Methods, each on the same arrays in the same run:

* rodwarp: ``rodwarp.analysis.linking_number`` and ``average_crossing_number`` (closed form per
  segment pair, one Warp launch each; the timed call is ``average_crossing_number``, which
  evaluates every pair once).
* NumPy: ``rodwarp.testing.reference.gauss_linking_numpy`` (the fan-from-the-foot form, no shared code
  with the Warp kernel) over all n^2 segment pairs in blocks, summed with ``math.fsum``: the
  signed sum and the sum of |G| from one pass.
* PyElastica (if installed): its numba Klenin & Langowski (2000) per-pair solid angle
  ``elastica.rod.knot_theory._compute_link`` (the kernel of ``elastica.compute_link``, signed
  sum only).
* pyknotid 0.5.3, when an interpreter that runs it is named by ``RODWARP_PYKNOTID_PYTHON``
  (it needs NumPy < 1.24, so it cannot share the project's environment; see
  ``benchmarks/README.md``), run in a subprocess that times only the calls:
  the linking number of closed curves from its projection crossing finder (Cython), as
  ``sum of crossing signs / 2`` from ``Link.raw_crossings()`` (``Link.linking_number()`` itself
  returns |2 Lk|: every crossing is listed once per component; recorded), and the exact Gauss
  sum and ACN of the pair from its pure-Python Klenin-Langowski integral
  ``writhe_and_acn_integral`` by inclusion-exclusion over the concatenated curve a-J-b
  (J the joining segment): X(a, b) = [W(aJb) - W(aJ) - W(Jb)] / 2 (W: pyknotid's writhe or
  ACN, which count each pair twice), on the random open walks only (the integral ignores its
  ``closed`` flag, and closing a polygon by repeating its first vertex makes two non-adjacent
  segments share a vertex, which it turns into NaN) and only up to n = 100 (quick) / 200
  (full) segments: it loops over pairs in Python (about 0.2 ms per pair here), so it is timed once.

Timing: median of 3 (quick) / 5 (full) repeats (rodwarp after one untimed call: Warp compiles
and loads its module on first use; numba compiles PyElastica's kernel on a small call first).
Agreement: max |difference| from rodwarp per method and quantity.  Ratio:
rodwarp time / peer time (< 1: rodwarp faster).
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks import common
from benchmarks.common import fmt, log

NAME = "acn_peer"
TITLE = "ACN and linking number: rodwarp against NumPy, PyElastica and pyknotid"
FAMILIES = ("hopf", "torus_k2", "torus_k5", "random_closed", "random_open")
LABELS = {"hopf": "Hopf link", "torus_k2": "torus link T(2,4)", "torus_k5": "torus link T(2,10)",
          "random_closed": "random closed polygons", "random_open": "random open walks"}
PK_ENV = "RODWARP_PYKNOTID_PYTHON"


# ----------------------------------------------------------------------------------------------
# curves
# ----------------------------------------------------------------------------------------------

def _rotation(seed: int = 5) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


def curves(family: str, n: int, seed: int = 0):
    """(a, b, closed, exact |Lk| or None): two curves of n segments each."""
    R = _rotation()
    if family == "hopf":
        t = 2 * np.pi * np.arange(n) / n
        a = np.stack([np.cos(t), np.sin(t), 0 * t], 1)
        b = np.stack([1 + np.cos(t), 0 * t, np.sin(t)], 1)
        return a @ R.T, b @ R.T, True, 1
    if family.startswith("torus_k"):
        k = int(family[len("torus_k"):])
        s = 2 * np.pi * np.arange(n) / n

        def comp(shift):
            phi = k * s + shift
            return np.stack([(2 + np.cos(phi)) * np.cos(s), (2 + np.cos(phi)) * np.sin(s), np.sin(phi)], 1)

        return comp(0.0) @ R.T, comp(np.pi) @ R.T, True, k
    rng = np.random.default_rng(seed + 1000 * n + (7 if family == "random_open" else 0))

    def walk(closed):
        steps = rng.standard_normal((n if closed else n, 3))
        if closed:
            steps -= steps.mean(0)  # closes: the n steps sum to zero
            pts = np.cumsum(steps, 0)[:n]  # n distinct vertices, the last step returns to the first
        else:
            pts = np.concatenate([np.zeros((1, 3)), np.cumsum(steps, 0)])  # n + 1 vertices
        pts -= pts.mean(0)
        return pts / np.sqrt((pts ** 2).sum(1).mean())

    closed = family == "random_closed"
    a = walk(closed)
    b = walk(closed) + np.array([0.3, 0.0, 0.0])
    return a, b, closed, None


# ----------------------------------------------------------------------------------------------
# methods
# ----------------------------------------------------------------------------------------------

def _segments(p, closed):
    return (p, np.roll(p, -1, axis=0)) if closed else (p[:-1], p[1:])


def numpy_sums(a, b, closed: bool, block: int = 1 << 18):
    """(signed sum, sum of |G|) over all segment pairs with rodwarp.testing.reference (NumPy)."""
    from rodwarp.testing.reference import gauss_linking_numpy

    a0, a1 = _segments(a, closed)
    b0, b1 = _segments(b, closed)
    nb = len(b0)
    rows = max(1, block // nb)
    s, sa = [], []
    for i in range(0, len(a0), rows):
        ii = slice(i, i + rows)
        m = len(a0[ii])
        g = gauss_linking_numpy(np.repeat(a0[ii], nb, 0), np.repeat(a1[ii], nb, 0), np.tile(b0, (m, 1)),
                                np.tile(b1, (m, 1)))
        s.append(math.fsum(g))
        sa.append(math.fsum(np.abs(g)))
    return math.fsum(s), math.fsum(sa)


def _pyelastica_link():
    try:
        from elastica.rod.knot_theory import _compute_link
    except Exception as e:  # noqa: BLE001 - not installed, or numba fails to load
        return None, f"{type(e).__name__}: {e}"
    return _compute_link, None


def pyelastica_sum(fn, a, b, closed: bool) -> float:
    if closed:
        a = np.vstack([a, a[:1]])
        b = np.vstack([b, b[:1]])
    return float(fn(np.ascontiguousarray(a.T[None]), np.ascontiguousarray(b.T[None]))[0])


PYKNOTID_SCRIPT = r'''
import json, math, sys, time
import numpy as np
import pyknotid
from pyknotid.spacecurves import Link
from pyknotid.spacecurves.complexity import writhe_and_acn_integral
try:
    from pyknotid.spacecurves import chelpers  # noqa: F401
    cython = True
except ImportError:
    cython = False
data = np.load(sys.argv[1])
cfg = json.loads(sys.argv[2])
reps, nmax = cfg["repeats"], cfg["integral_max_n"]

def timed(fn, n):
    """Result and n timings of fn, after one untimed call when n > 1."""
    out = fn() if n > 1 else None
    ts = []
    for _ in range(n):
        t = time.perf_counter(); out = fn(); ts.append(time.perf_counter() - t)
    return out, ts

def crossings_lk(a, b):
    L = Link([a, b], verbose=False)
    c = L.raw_crossings()
    return float(np.sum(c[0][:, 3]) / 2.0) if len(c[0]) else 0.0, float(L.linking_number())

def integral(a, b, closed):
    # open curves only: writhe_and_acn_integral ignores its closed flag, and closing a polygon by
    # repeating its first vertex makes a non-adjacent pair share a vertex (0/0 -> NaN)
    w_ajb, c_ajb = writhe_and_acn_integral(np.vstack([a, b]))
    w_aj, c_aj = writhe_and_acn_integral(np.vstack([a, b[:1]]))
    w_jb, c_jb = writhe_and_acn_integral(np.vstack([a[-1:], b]))
    return (w_ajb - w_aj - w_jb) / 2.0, (c_ajb - c_aj - c_jb) / 2.0

out = {"version": pyknotid.__version__ if hasattr(pyknotid, "__version__") else "unknown",
       "numpy": np.__version__, "cython_helpers": cython, "python": sys.version.split()[0], "cases": []}
for key in cfg["cases"]:
    a, b = data[key + "_a"], data[key + "_b"]
    closed = bool(data[key + "_closed"])
    rec = {"key": key}
    if closed:
        (lk, raw), ts = timed(lambda: crossings_lk(a, b), reps)
        rec.update({"lk_crossings": lk, "link_linking_number": raw, "crossings_times_s": ts})
    if not closed and len(a) - 1 <= nmax:
        # pure Python, nothing to warm up: one timed call
        (s, acn), ts = timed(lambda: integral(a, b, closed), 1)
        rec.update({"integral_signed": s, "integral_acn": acn, "integral_times_s": ts})
    out["cases"].append(rec)
    print(key, {k: v for k, v in rec.items() if not k.endswith("times_s")}, flush=True, file=sys.stderr)
json.dump(out, open(sys.argv[3], "w"))
'''


def _run_pyknotid(cases: dict, quick: bool, repeats: int) -> dict:
    py = os.environ.get(PK_ENV)
    if not py:
        return {"ran": False, "reason": (f"{PK_ENV} is not set: pyknotid 0.5.3 needs NumPy < 1.24 (it uses np.float), "
                                         "so it cannot run in the project's environment; see benchmarks/README.md")}
    with tempfile.TemporaryDirectory() as tmp:
        npz = Path(tmp) / "curves.npz"
        arrays = {}
        for key, (a, b, closed) in cases.items():
            arrays[key + "_a"], arrays[key + "_b"], arrays[key + "_closed"] = a, b, np.array(closed)
        np.savez(npz, **arrays)
        out = Path(tmp) / "out.json"
        cfg = {"repeats": repeats, "integral_max_n": 100 if quick else 200, "cases": list(cases)}
        t0 = time.perf_counter()
        try:
            p = subprocess.run([py, "-c", PYKNOTID_SCRIPT, str(npz), json.dumps(cfg), str(out)], capture_output=True,
                               text=True, timeout=3000)
        except (OSError, subprocess.SubprocessError) as e:
            return {"ran": False, "reason": f"could not start {py}: {type(e).__name__}: {e}"}
        if p.returncode != 0 or not out.exists():
            tail = (p.stderr or "").strip().splitlines()[-3:]
            return {"ran": False, "reason": f"{py} failed (exit {p.returncode}): {' | '.join(tail)}"}
        res = json.loads(out.read_text())
    res.update({"ran": True, "interpreter": py, "subprocess_wall_s": time.perf_counter() - t0})
    return res


# ----------------------------------------------------------------------------------------------
# run
# ----------------------------------------------------------------------------------------------

def _timed(fn, repeats: int, warmup: bool):
    """(result of the last call, spread of ``repeats`` wall times); one untimed call first with
    ``warmup`` (Warp's first launch)."""
    if warmup:
        fn()
    ts, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t)
    return out, common.spread(ts)


def run(quick: bool, device: str) -> dict:
    from rodwarp import _warp
    from rodwarp.analysis import average_crossing_number, linking_number

    _warp.init()
    from benchmarks.bench_acn import _warm_allocator

    _warm_allocator()
    repeats = common.n_repeats(quick)
    sizes = [100, 300, 1000, 2000] if quick else [100, 200, 500, 1000, 2000, 3000]
    pe_fn, pe_why = _pyelastica_link()
    if pe_fn is not None:  # numba compile
        pe_fn(np.random.rand(1, 3, 5), np.random.rand(1, 3, 5))
    linking_number(*curves("hopf", 8)[:2], closed=True, device=device)  # Warp compile

    cases, rows = {}, []
    for fam in FAMILIES:
        for n in sizes:
            a, b, closed, exact = curves(fam, n)
            key = f"{fam}_{n}"
            cases[key] = (a, b, closed)
            lk = linking_number(a, b, closed=closed, device=device)
            acn, t_rw = _timed(lambda: average_crossing_number(a, b, closed=closed, device=device), repeats, True)
            (s_np, acn_np), t_np = _timed(lambda: numpy_sums(a, b, closed), repeats, False)
            row = {"family": fam, "n_segments": n, "pairs": n * n, "closed": closed, "exact_abs_lk": exact,
                   "rodwarp": {"lk": lk, "acn": acn, "time_s": t_rw},
                   "numpy": {"lk": s_np, "acn": acn_np, "time_s": t_np, "lk_diff": s_np - lk, "acn_diff": acn_np - acn,
                             "rodwarp_over_peer": t_rw["median"] / t_np["median"]}}
            if pe_fn is not None:
                s_pe, t_pe = _timed(lambda: pyelastica_sum(pe_fn, a, b, closed), repeats, False)
                row["pyelastica"] = {"lk": s_pe, "lk_diff": s_pe - lk, "time_s": t_pe,
                                     "rodwarp_over_peer": t_rw["median"] / t_pe["median"]}
            rows.append(row)
            log(f"{LABELS[fam]}, n = {n}: rodwarp Lk {lk:.12g} ACN {acn:.10g} ({fmt(t_rw['median'] * 1e3)} ms); "
                f"NumPy dLk {fmt(row['numpy']['lk_diff'])} dACN {fmt(row['numpy']['acn_diff'])} "
                f"({fmt(t_np['median'] * 1e3)} ms)"
                + (f"; PyElastica dLk {fmt(row['pyelastica']['lk_diff'])} ({fmt(row['pyelastica']['time_s']['median'] * 1e3)} ms)"
                   if "pyelastica" in row else ""))

    pk = _run_pyknotid(cases, quick, repeats)
    if pk.get("ran"):
        by = {c["key"]: c for c in pk.pop("cases")}
        for row in rows:
            c = by.get(f"{row['family']}_{row['n_segments']}", {})
            d = {}
            if "lk_crossings" in c:
                t = common.spread(c["crossings_times_s"])
                d.update({"lk_crossings": c["lk_crossings"], "lk_crossings_diff": c["lk_crossings"] - row["rodwarp"]["lk"],
                          "link_linking_number": c["link_linking_number"], "crossings_time_s": t,
                          "rodwarp_over_crossings": row["rodwarp"]["time_s"]["median"] / t["median"]})
            if "integral_signed" in c:
                t = common.spread(c["integral_times_s"])
                d.update({"integral_lk": c["integral_signed"], "integral_acn": c["integral_acn"],
                          "integral_lk_diff": c["integral_signed"] - row["rodwarp"]["lk"],
                          "integral_acn_diff": c["integral_acn"] - row["rodwarp"]["acn"], "integral_time_s": t,
                          "rodwarp_over_integral": row["rodwarp"]["time_s"]["median"] / t["median"]})
            if d:
                row["pyknotid"] = d
        log(f"pyknotid {pk.get('version')} (NumPy {pk.get('numpy')}, Cython helpers {pk.get('cython_helpers')}) ran "
            f"in {pk['subprocess_wall_s']:.1f} s")
    else:
        log(f"pyknotid not run: {pk['reason']}")

    def maxabs(method, key):
        v = [abs(r[method][key]) for r in rows if method in r and r[method].get(key) is not None]
        return max(v) if v else None

    agreement = {"numpy_lk": maxabs("numpy", "lk_diff"), "numpy_acn": maxabs("numpy", "acn_diff"),
                 "pyelastica_lk": maxabs("pyelastica", "lk_diff"),
                 "pyknotid_crossings_lk": maxabs("pyknotid", "lk_crossings_diff"),
                 "pyknotid_integral_lk": maxabs("pyknotid", "integral_lk_diff"),
                 "pyknotid_integral_acn": maxabs("pyknotid", "integral_acn_diff")}
    exact_dev = max(abs(abs(r["rodwarp"]["lk"]) - r["exact_abs_lk"]) for r in rows if r["exact_abs_lk"] is not None)
    closed_int = max(abs(r["rodwarp"]["lk"] - round(r["rodwarp"]["lk"])) for r in rows if r["closed"])
    problems = []
    if agreement["numpy_lk"] > 1e-9 or agreement["numpy_acn"] > 1e-9 * max(r["rodwarp"]["acn"] for r in rows):
        problems.append(f"rodwarp and NumPy disagree: max |dLk| {agreement['numpy_lk']:.3g}, "
                        f"max |dACN| {agreement['numpy_acn']:.3g}")
    if exact_dev > 1e-9:
        problems.append(f"rodwarp's linking number of a Hopf/torus link is off the exact value by {exact_dev:.3g}")
    if agreement["pyknotid_crossings_lk"] is not None and agreement["pyknotid_crossings_lk"] > 1e-6:
        problems.append(f"pyknotid's crossing-sign linking number differs from rodwarp's by up to "
                        f"{agreement['pyknotid_crossings_lk']:.3g}")
    return {"title": TITLE, "sizes": sizes, "families": list(FAMILIES), "rows": rows, "agreement": agreement,
            "rodwarp_max_dev_from_exact_lk": exact_dev, "rodwarp_max_dev_from_integer_closed": closed_int,
            "pyelastica": {"available": pe_fn is not None, "reason": pe_why,
                           "version": _dist_version("pyelastica")},
            "pyknotid": pk, "settings": {"repeats": repeats, "timed_rodwarp_call": "average_crossing_number",
                                         "numpy_form": "foot", "numpy_block_pairs": 1 << 18},
            "problems": problems}


def _dist_version(name):
    import importlib.metadata

    try:
        return importlib.metadata.version(name)
    except importlib.metadata.PackageNotFoundError:
        return None


# ----------------------------------------------------------------------------------------------
# report
# ----------------------------------------------------------------------------------------------

METHODS = (("rodwarp", "rodwarp (Warp CPU, closed form)", "C0", "o"),
           ("numpy", "NumPy reference (foot form)", "C2", "s"),
           ("pyelastica", "PyElastica K&L (numba, Lk only)", "C3", "^"),
           ("pyknotid_crossings", "pyknotid crossings (Cython, Lk of closed curves)", "C1", "v"),
           ("pyknotid_integral", "pyknotid K&L integral (pure Python)", "C4", "D"))


def _time(row, method):
    if method in ("rodwarp", "numpy", "pyelastica"):
        return (row.get(method) or {}).get("time_s", {}).get("median")
    pk = row.get("pyknotid") or {}
    key = "crossings_time_s" if method == "pyknotid_crossings" else "integral_time_s"
    return (pk.get(key) or {}).get("median")


def _ratio_at(rec, method, n):
    rr = [r for r in rec["rows"] if r["n_segments"] == n and _time(r, method)]
    if not rr:
        return None
    return float(np.median([_time(r, "rodwarp") / _time(r, method) for r in rr]))


def summary(rec: dict) -> list[dict]:
    rows = []
    ag = rec["agreement"]
    sizes = rec["sizes"]
    big = max(sizes)
    rw_big = [r["rodwarp"]["time_s"]["median"] for r in rec["rows"] if r["n_segments"] == big]
    np_big = [r["numpy"]["time_s"]["median"] for r in rec["rows"] if r["n_segments"] == big]
    rows.append({"benchmark": (f"ACN + Lk of two curves, {big} segments each ({big * big:,} pairs), median over "
                               f"{len(rw_big)} curve families (ratio rodwarp / NumPy time)"),
                 "rodwarp": f"{fmt(float(np.median(rw_big)) * 1e3)} ms",
                 "peer": (f"NumPy rodwarp.testing.reference: {fmt(float(np.median(np_big)) * 1e3)} ms; max |dLk| "
                          f"{fmt(ag['numpy_lk'])}, max |dACN| {fmt(ag['numpy_acn'])} over all cases"),
                 "ratio": _ratio_at(rec, "numpy", big)})
    if rec["pyelastica"]["available"]:
        pe_big = [r["pyelastica"]["time_s"]["median"] for r in rec["rows"] if r["n_segments"] == big]
        rows.append({"benchmark": f"Lk of two curves, {big} segments each: PyElastica Klenin-Langowski (numba) "
                                  "(ratio rodwarp / PyElastica time)",
                     "rodwarp": f"{fmt(float(np.median(rw_big)) * 1e3)} ms (ACN and Lk)",
                     "peer": (f"PyElastica {rec['pyelastica']['version']}: {fmt(float(np.median(pe_big)) * 1e3)} ms; "
                              f"max |dLk| {fmt(ag['pyelastica_lk'])}"),
                     "ratio": _ratio_at(rec, "pyelastica", big)})
    pk = rec["pyknotid"]
    if pk.get("ran"):
        closed = [r for r in rec["rows"] if r["closed"] and r.get("pyknotid", {}).get("lk_crossings") is not None]
        raw = sorted({(abs(round(r["rodwarp"]["lk"])), r["pyknotid"]["link_linking_number"]) for r in closed})
        rows.append({"benchmark": f"Lk of closed curves, {big} segments each: pyknotid crossing signs (Cython) "
                                  "(ratio rodwarp / pyknotid time)",
                     "rodwarp": "closed form, all pairs",
                     "peer": (f"pyknotid {pk.get('version')} (NumPy {pk.get('numpy')}): max |dLk| "
                              f"{fmt(ag['pyknotid_crossings_lk'])}; Link.linking_number() returns "
                              + ", ".join(f"{v:g} for |Lk| = {k}" for k, v in raw)),
                     "ratio": _ratio_at(rec, "pyknotid_crossings", big)})
        ns = sorted({r["n_segments"] for r in rec["rows"] if r.get("pyknotid", {}).get("integral_acn") is not None})
        if ns:
            rows.append({"benchmark": (f"ACN + Lk, {ns[-1]} segments each: pyknotid writhe_and_acn_integral "
                                       "(pure Python, inclusion-exclusion) (ratio rodwarp / pyknotid time)"),
                         "rodwarp": "closed form",
                         "peer": (f"max |dLk| {fmt(ag['pyknotid_integral_lk'])}, max |dACN| "
                                  f"{fmt(ag['pyknotid_integral_acn'])} (n <= {ns[-1]})"),
                         "ratio": _ratio_at(rec, "pyknotid_integral", ns[-1])})
    else:
        rows.append({"benchmark": "pyknotid", "rodwarp": "—", "peer": f"not run: {pk.get('reason')}", "ratio": None})
    rows.append({"benchmark": "rodwarp Lk of Hopf and torus links against the exact integer",
                 "rodwarp": f"max deviation {fmt(rec['rodwarp_max_dev_from_exact_lk'])}",
                 "peer": f"closed random polygons: max distance from an integer {fmt(rec['rodwarp_max_dev_from_integer_closed'])}",
                 "ratio": None})
    return rows


def plot(rec: dict, outdir) -> list[dict]:
    plt = common.pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(14, 5.4))
    ax = axes[0]
    sizes = rec["sizes"]
    drawn = []
    for method, label, col, mk in METHODS:
        xs, med, lo, hi = [], [], [], []
        for n in sizes:
            t = [_time(r, method) for r in rec["rows"] if r["n_segments"] == n and _time(r, method)]
            if t:
                xs.append(n)
                med.append(np.median(t))
                lo.append(min(t))
                hi.append(max(t))
        if xs:
            med, lo, hi = np.array(med), np.array(lo), np.array(hi)
            ax.errorbar(xs, med, yerr=[med - lo, hi - med], marker=mk, color=col, capsize=3, label=label)
            drawn.append(method)
    ref = np.array(sizes, float)
    t0 = _time(next(r for r in rec["rows"] if r["n_segments"] == sizes[-1]), "rodwarp")
    ax.plot(ref, t0 * (ref / ref[-1]) ** 2, "k:", lw=0.8, label="slope 2 (all n² pairs)")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("segments per curve n (n² segment pairs)")
    ax.set_ylabel("time per evaluation (s; median over families, bars: min–max)")
    ax.set_title("Time against curve size, same run", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)

    ax = axes[1]
    floor = 1e-17
    for method, key, label, col, mk in (
            ("numpy", "lk_diff", "NumPy: |ΔLk|", "C2", "s"), ("numpy", "acn_diff", "NumPy: |ΔACN|", "C2", "x"),
            ("pyelastica", "lk_diff", "PyElastica K&L: |ΔLk|", "C3", "^"),
            ("pyknotid", "lk_crossings_diff", "pyknotid crossings: |ΔLk|", "C1", "v"),
            ("pyknotid", "integral_lk_diff", "pyknotid integral: |ΔLk|", "C4", "D"),
            ("pyknotid", "integral_acn_diff", "pyknotid integral: |ΔACN|", "C4", "+")):
        pts = [(r["n_segments"], abs(r[method][key])) for r in rec["rows"] if method in r and r[method].get(key) is not None]
        if pts:
            jitter = {"lk_diff": 0.97, "acn_diff": 1.03}.get(key, 1.0)
            ax.plot([p[0] * jitter for p in pts], [max(p[1], floor) for p in pts], mk, color=col, ms=5, label=label,
                    mfc="none" if mk not in ("x", "+") else None)
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("segments per curve n")
    ax.set_ylabel(f"|peer − rodwarp| (exact zeros drawn at {floor:g})")
    ax.set_title("Agreement with rodwarp, every curve pair", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle(f"ACN and linking number: rodwarp against independent implementations, {common.short_device(rec)}",
                 fontsize=11)
    fig.tight_layout()
    f = common.save_figure(fig, outdir / f"{NAME}.png")
    ag = rec["agreement"]
    big = sizes[-1]
    parts = [f"Left: time per evaluation of two curves against n (log-log); at n = {big} ({big * big:,} pairs) rodwarp "
             f"takes {fmt(_ratio_at(rec, 'numpy', big))}x the NumPy reference's time"]
    if "pyelastica" in drawn:
        parts.append(f"{fmt(_ratio_at(rec, 'pyelastica', big))}x PyElastica's numba Klenin-Langowski sum (Lk only)")
    if "pyknotid_crossings" in drawn:
        parts.append(f"{fmt(_ratio_at(rec, 'pyknotid_crossings', big))}x pyknotid's Cython crossing finder (integer Lk "
                     f"of closed curves only, from one projection)")
    if "pyknotid_integral" in drawn:
        ns = max(r["n_segments"] for r in rec["rows"] if _time(r, "pyknotid_integral"))
        parts.append(f"and {fmt(_ratio_at(rec, 'pyknotid_integral', ns))}x pyknotid's pure-Python integral at n = {ns}")
    reading = ", ".join(parts) + ". "
    reading += (f"Right: |difference from rodwarp| for every curve pair: NumPy within {fmt(ag['numpy_lk'])} (Lk) and "
                f"{fmt(ag['numpy_acn'])} (ACN)")
    if ag.get("pyelastica_lk") is not None:
        reading += f", PyElastica within {fmt(ag['pyelastica_lk'])} (Lk)"
    if ag.get("pyknotid_crossings_lk") is not None:
        reading += f", pyknotid crossings within {fmt(ag['pyknotid_crossings_lk'])} (Lk)"
    if ag.get("pyknotid_integral_acn") is not None:
        reading += (f", pyknotid integral within {fmt(ag['pyknotid_integral_lk'])} (Lk) and "
                    f"{fmt(ag['pyknotid_integral_acn'])} (ACN)")
    reading += (f". rodwarp's Lk of the Hopf and torus links is within {fmt(rec['rodwarp_max_dev_from_exact_lk'])} of "
                f"the exact integer.")
    if not rec["pyknotid"].get("ran"):
        reading += f" pyknotid not run: {rec['pyknotid'].get('reason')}"
    return [{"file": f, "title": "ACN and linking number against independent implementations", "reading": reading}]
