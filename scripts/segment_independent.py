"""Segmentation scored on two phantom generators (issue 50's benchmark table).

Two regimes, each at radii 1.5, 2 and 3 voxels in 96 x 128 x 128 volumes, each built by two
generators:

- ``independent``: :mod:`rodwarp.testing.ct_generator`, which shares no code with ``rodwarp
  phantom``. Bundles: :func:`touching_bundles` (2-5 parallel rods touching with zero gap,
  within 25 degrees of horizontal, six crossing rods laid on them, rod length 28 r + 14).
  Wires: :func:`wire_tangle` with ``touching=True`` (8 curved wires, most touching one or two
  of the wires they cross at zero gap). Rendered by its own image model (analytic partial
  volume, PSF with a scatter tail, Poisson noise, beam hardening, rings). True contacts are the
  pairs built to touch (gap 0); every other pair is at least a voxel apart.
- ``rodwarp``: the project's own phantom API (:mod:`rodwarp.ct`). Bundles:
  ``scene_bundles`` (6 bundles of 2-5 rods, closest packed, random orientations, the same
  length) plus three crossing pairs, each a two-rod ``scene_random_packing`` (the second rod
  placed touching the first), kept when both rods are 2 voxels clear of every rod placed
  before (the composition ``make_case("dense_bundles")`` uses). Wires: ``scene_wire_tangle``
  (10 wires of length 120-180 voxels; wires may touch, never overlap). Rendered by
  ``render_phantom`` at its defaults (Gaussian blur 1 voxel, CNR 10). True contacts are its own
  truth, ``phantom_truth`` (gap <= 0.5 voxel), scored with ``touch_tol=0.5``.

For each seed (``--seeds`` of them, drawn by ``np.random.SeedSequence``; ``--entropy`` repeats a
draw), every scene is segmented by ``rodwarp.ct.segment_volume`` at its defaults and scored:
rods with ``match_rods`` (bundles) or ``match_polylines`` (wires), contacts with
``score_contacts`` through that matching.

``--code PATH`` scores another code tree (e.g. a ``git worktree`` of an older commit): its
``rodwarp`` is imported in place of this checkout's (``rodwarp.ct``: the segmentation, the
scoring and the rodwarp phantom). The independent generator is always loaded from this
checkout's ``rodwarp/testing/ct_generator.py`` by file path, so before and after see the same
scenes; each row records a hash of the scanned volume to check that they do.

It writes ``benchmarks/results/segment_independent_<label>.{json,md}``: per regime, generator and
radius, the median and worst rod F1 and contact recall over the seeds, with every seed's row.

    git worktree add /tmp/wt_before 7aadaac
    python scripts/segment_independent.py --code /tmp/wt_before --label before
    python scripts/segment_independent.py --label after --entropy <the before run's entropy>
"""

from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "benchmarks" / "results"
RADII = (1.5, 2.0, 3.0)
SHAPE = (96, 128, 128)
GENERATORS = ("independent", "rodwarp")


def _generator_module():
    """This checkout's independent generator, by file path (it imports nothing of rodwarp)."""
    path = ROOT / "rodwarp" / "testing" / "ct_generator.py"
    spec = importlib.util.spec_from_file_location("_independent_ct_generator", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod  # dataclasses look the module up
    spec.loader.exec_module(mod)
    return mod


def _rod_length(radius: float) -> float:
    return 28.0 * radius + 14.0


def independent_scene(regime: str, radius: float, seed: int):
    """(volume, true RodSet with contacts, touch_tol) from the independent generator."""
    from rodwarp.ct import phantom_truth
    from rodwarp.rodset import RodSet

    g = _generator_module()
    if regime == "bundles":
        scene = g.touching_bundles(shape=SHAPE, radius=radius, length=_rod_length(radius), seed=seed)
    else:
        scene = g.wire_tangle(shape=SHAPE, radius=radius, seed=seed, touching=True)
    vol = g.render(scene, seed=seed)
    truth = RodSet.from_polylines(scene.polylines, radii=[float(scene.radius[scene.rod == k][0])
                                                          for k in range(scene.n_rods)], units="voxel")
    # the generator's contacts are exact (gap 0, others >= 1 voxel): the geometry finds them again
    truth.contacts = phantom_truth(truth, 1e-3)
    found = {(int(i), int(j)) for i, j in zip(truth.contacts.rod_i, truth.contacts.rod_j)}
    if found != {tuple(c) for c in scene.contacts}:
        raise AssertionError(f"the geometry's contacts differ from the generator's for {regime} r {radius} "
                             f"seed {seed}: {sorted(found)} vs {scene.contacts}")
    return vol, truth, 1e-3


def rodwarp_scene(regime: str, radius: float, seed: int):
    """(volume, true RodSet with contacts, touch_tol) from rodwarp's own phantom API."""
    from rodwarp.ct import phantom_truth, render_phantom, scene_bundles, scene_random_packing, scene_wire_tangle
    from rodwarp.errors import RodwarpError
    from rodwarp.rodset import RodSet, segment_distance

    r = float(radius)
    if regime == "bundles":
        L = _rod_length(r)
        bun = scene_bundles(SHAPE, n_bundles=6, sizes=(2, 5), radius=r, length=L, seed=seed)
        polys = [bun.rod(k) for k in range(bun.n_rods)]
        pairs = 0
        for j in range(400):
            if pairs == 3:
                break
            try:
                pk = scene_random_packing(SHAPE, n_rods=2, radius=r, aspect=L / (2 * r), touching_fraction=1.0,
                                          seed=seed * 1000 + j + 1, max_attempts=2000)
            except RodwarpError:
                continue
            A = np.array([p[0] for p in polys])
            B = np.array([p[-1] for p in polys])
            a, b = pk.points[0::2], pk.points[1::2]
            d = segment_distance(a[:, None], b[:, None], A[None], B[None])
            if d.min() >= 2 * r + 2.0:
                polys += [pk.rod(0), pk.rod(1)]
                pairs += 1
        truth = RodSet.from_polylines(polys, r, units="voxel")
    else:
        truth = scene_wire_tangle(SHAPE, n_wires=10, radius=r, length=(120.0, 180.0), seed=seed)
    truth.contacts = phantom_truth(truth)
    vol = render_phantom(truth, SHAPE, seed=seed)
    return vol, truth, 0.5


def run_one(regime: str, generator: str, radius: float, seed: int) -> dict:
    from rodwarp.ct import match_polylines, match_rods, score_contacts, segment_volume
    from rodwarp.errors import RodwarpError

    t0 = time.perf_counter()
    vol, truth, touch_tol = (independent_scene if generator == "independent" else rodwarp_scene)(regime, radius, seed)
    scene_s = time.perf_counter() - t0
    c = truth.contacts
    n_contacts = len({(int(i), int(j)) for i, j, g in zip(c.rod_i, c.rod_j, c.gap) if g <= touch_tol})
    row = {"regime": regime, "generator": generator, "radius": radius, "seed": seed, "n_true": int(truth.n_rods),
           "true_contacts": n_contacts, "volume_sha1": hashlib.sha1(vol.tobytes()).hexdigest()[:16],
           "scene_s": scene_s}
    t0 = time.perf_counter()
    try:
        res = segment_volume(vol)
    except RodwarpError as e:
        row.update(error=str(e), rod_f1=0.0, contact_recall=0.0 if n_contacts else None, segment_s=None)
        return row
    row["segment_s"] = time.perf_counter() - t0
    # which path the segmentation took (it switches to curved tracing by itself) and what it measured
    row.update(path=str((res.rods.attrs or {}).get("shape", "straight")), diameter_found=float(res.diameter),
               foreground_explained=res.quality.get("foreground_explained"))
    m = match_rods(res.rods, truth) if regime == "bundles" else match_polylines(res.rods, truth)
    row.update(n_found=int(m.n_found), rod_f1=float(m.f1), rod_precision=float(m.precision),
               rod_recall=float(m.recall))
    c = score_contacts(res.contacts, truth, m, touch_tol=touch_tol)
    row.update(contact_recall=float(c.recall) if c.tp + c.fn else None,
               contact_precision=float(c.precision) if c.tp + c.fp else None)
    return row


def _git(tree: Path, *args) -> str:
    return subprocess.run(["git", "-C", str(tree), *args], capture_output=True, text=True).stdout.strip()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--entropy", type=int, default=None, help="repeat an earlier draw of seeds")
    ap.add_argument("--label", default="before", help="the code state scored (before, after)")
    ap.add_argument("--regimes", default="bundles,wires")
    ap.add_argument("--generators", default=",".join(GENERATORS))
    ap.add_argument("--radii", default=",".join(f"{r:g}" for r in RADII))
    ap.add_argument("--code", default=None, help="score this code tree's rodwarp (e.g. a git worktree) "
                                                 "instead of this checkout's")
    ap.add_argument("--chart", action="store_true", help="only draw segment_independent.png from the before "
                                                       "and after results already written")
    a = ap.parse_args()
    if a.chart:
        return chart()
    code = Path(a.code).resolve() if a.code else ROOT
    if a.code:
        if not (code / "rodwarp" / "__init__.py").is_file():
            ap.error(f"--code {a.code}: no rodwarp package there")
        sys.path.insert(0, str(code))
    import rodwarp

    if Path(rodwarp.__file__).resolve().parent != code / "rodwarp":
        raise SystemExit(f"rodwarp was imported from {rodwarp.__file__}, not from {code}")
    regimes = a.regimes.split(",")
    generators = a.generators.split(",")
    radii = [float(v) for v in a.radii.split(",")]
    ss = np.random.SeedSequence(a.entropy)
    seeds = [int(s) for s in ss.generate_state(a.seeds, dtype=np.uint32)]
    rows = []
    t_all = time.perf_counter()
    for regime in regimes:
        for gen in generators:
            for r in radii:
                for s in seeds:
                    row = run_one(regime, gen, r, s)
                    rows.append(row)
                    print(json.dumps(row), flush=True)
    total_s = time.perf_counter() - t_all
    fmed = lambda v: statistics.median(v) if v else None  # noqa: E731
    summary = []
    for regime in regimes:
        for gen in generators:
            for r in radii:
                sel = [x for x in rows if x["regime"] == regime and x["generator"] == gen and x["radius"] == r]
                f1 = [x["rod_f1"] for x in sel]
                cr = [x["contact_recall"] for x in sel if x.get("contact_recall") is not None]
                summary.append({"regime": regime, "generator": gen, "radius": r, "n": len(sel),
                                "rod_f1_median": fmed(f1), "rod_f1_worst": min(f1),
                                "contact_recall_median": fmed(cr), "contact_recall_worst": min(cr) if cr else None,
                                "n_with_contacts": len(cr),
                                "true_contacts_median": fmed([x["true_contacts"] for x in sel]),
                                "segment_s_median": fmed([x["segment_s"] for x in sel if x.get("segment_s")]),
                                "n_curved_path": sum(1 for x in sel if x.get("path") == "curved")})
    head = _git(code, "rev-parse", "--short", "HEAD")
    dirty = bool(_git(code, "status", "--porcelain", "--", "rodwarp"))
    gen_head = _git(ROOT, "log", "-1", "--format=%h", "--", "rodwarp/testing/ct_generator.py")
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo") if ln.startswith("model name")), "")
    cmd = f"python scripts/segment_independent.py --seeds {a.seeds} --entropy {ss.entropy} --label {a.label}"
    if a.code:
        cmd += f" --code {a.code}"
    out = {"label": a.label, "commit": head, "rodwarp_dirty": dirty, "code": str(code),
           "generator_commit": gen_head, "entropy": ss.entropy, "seeds": seeds, "summary": summary, "rows": rows,
           "total_s": total_s, "cpu": cpu, "python": platform.python_version(), "command": cmd}
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / f"segment_independent_{a.label}.json").write_text(json.dumps(out, indent=1))
    fmt = lambda v: "-" if v is None else f"{v:.3f}"  # noqa: E731
    lines = [f"# Segmentation on two phantom generators ({a.label}: rodwarp at {head}"
             f"{' with uncommitted changes' if dirty else ''})", "",
             f"{cpu}; `{cmd}`; {total_s / 60:.1f} min in all; seeds drawn by the script: {seeds}.",
             f"Volumes {SHAPE[0]} x {SHAPE[1]} x {SHAPE[2]} voxels, segmented by `rodwarp.ct.segment_volume` at its "
             f"defaults. Generators: `independent` = `rodwarp.testing.ct_generator` at {gen_head} (bundles: "
             "`touching_bundles`, near-horizontal flat bundles of 2-5 rods with 6 crossing rods laid on them; wires: "
             "`wire_tangle(touching=True)`, 8 wires touching at zero gap where they cross); `rodwarp` = the project's "
             "own phantom (bundles: `scene_bundles`, 6 closest-packed bundles of 2-5 rods at random orientations, "
             "plus 3 touching crossing pairs from `scene_random_packing`; wires: `scene_wire_tangle`, 10 wires of "
             "length 120-180; `render_phantom` defaults). Rods scored by `match_rods` (bundles) or "
             "`match_polylines` (wires); contacts by `score_contacts` (independent: gap 0; rodwarp: its "
             "`phantom_truth`, gap <= 0.5 voxel). Contact recall over the seeds whose scene has true contacts. The "
             "last column counts the seeds on which `segment_volume` switched to its curved (filament) path.",
             "",
             "| regime | generator | radius (voxels) | seeds | rod F1 median | worst | contact recall median | "
             "worst | segment (s) median | true contacts median | seeds segmented as curved |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for s in summary:
        cr_n = "" if s["n_with_contacts"] in (0, s["n"]) else f" ({s['n_with_contacts']} seeds)"
        lines.append(f"| {s['regime']} | {s['generator']} | {s['radius']:g} | {s['n']} | {fmt(s['rod_f1_median'])} | "
                     f"{fmt(s['rod_f1_worst'])} | {fmt(s['contact_recall_median'])}{cr_n} | "
                     f"{fmt(s['contact_recall_worst'])} | "
                     f"{'-' if s['segment_s_median'] is None else format(s['segment_s_median'], '.1f')} | "
                     f"{s['true_contacts_median']:g} | {s['n_curved_path']} |")
    (OUT / f"segment_independent_{a.label}.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


def chart(out=OUT) -> int:
    """``segment_independent.png``: rod F1 and contact recall, median (bar) and worst seed (dot),
    before and after, for each regime, generator and radius."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = {lab: json.loads((out / f"segment_independent_{lab}.json").read_text()) for lab in ("before", "after")}
    summ = {lab: {(s["regime"], s["generator"], s["radius"]): s for s in r["summary"]} for lab, r in runs.items()}
    keys = [k for k in summ["after"] if k in summ["before"]]
    fig, axes = plt.subplots(2, 1, figsize=(12, 6.5), sharex=True)
    x = np.arange(len(keys))
    for ax, (field, name) in zip(axes, (("rod_f1", "rod F1"), ("contact_recall", "contact recall"))):
        for dx, lab, col in ((-0.2, "before", "0.6"), (0.2, "after", "tab:blue")):
            med = [summ[lab][k][f"{field}_median"] for k in keys]
            worst = [summ[lab][k][f"{field}_worst"] for k in keys]
            ax.bar(x + dx, [np.nan if v is None else v for v in med], 0.38, color=col, label=f"{lab}: median")
            ax.plot(x + dx, [np.nan if v is None else v for v in worst], "v", color="k" if lab == "after" else "0.3",
                    ms=5, label=f"{lab}: worst seed")
        ax.axhline(0.95 if field == "rod_f1" else 0.9, color="tab:red", lw=0.8, ls="--", label="target (median)")
        ax.set_ylim(0, 1.05)
        ax.set_ylabel(name)
    axes[0].legend(ncol=5, fontsize=8, loc="lower center", bbox_to_anchor=(0.5, 1.0), frameon=False)
    axes[1].set_xticks(x, [f"{k[0]}\n{k[1]}\nr {k[2]:g}" for k in keys], fontsize=8)
    fig.suptitle(f"segmentation on two phantom generators, 10 drawn seeds: before {runs['before']['commit']}, "
                 f"after {runs['after']['commit']}", fontsize=10)
    fig.tight_layout()
    fig.savefig(out / "segment_independent.png", dpi=110)
    print(out / "segment_independent.png")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
