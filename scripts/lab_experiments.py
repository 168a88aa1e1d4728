"""The paper's laboratory experiments in silico (docs/experiments.md): runs and report.

``run`` makes each lab run of a set that is not finished (``rodwarp simulate --protocol lab``,
one process at a time, continued with ``--resume`` where a killed run left checkpoints), so the
set can be stopped and started again across sessions:

    python scripts/lab_experiments.py run --set shake --runs RUNS_DIR [--alphas 38,66] [--seeds 0,1]
    python scripts/lab_experiments.py run --set press --runs RUNS_DIR
    python scripts/lab_experiments.py run --set container --runs RUNS_DIR

``report`` collects the finished runs' summary.json files into
``benchmarks/results/lab_experiments.json`` and ``.md`` and draws the figures: y_c(t)/y_c(0)
against cycles (Fig. 1E), the persistence against alpha (Fig. 1F), the lifted packings, and the
field statistics against strain beside the authors' experimental fields (their statistics from
``benchmarks/results/paper_fields.json``, and with ``--paper-fields DIR`` the means of n, phi, S
and c from the fields themselves):

    python scripts/lab_experiments.py report --runs RUNS_DIR [--paper-fields DIR]

The rods are the experiments' steel rods (l and d from the authors' data), real gravity, the
plate shaken at f = 5 Hz, A = 25 mm. The cylinder holds the rods that fill it to one rod length
at phi = 5.4 / alpha (``--fill-height``), radius one rod length unless a set says otherwise.
"""

from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "benchmarks" / "results"
#: the experiments' rods: alpha -> (length, m); d = l / alpha (the authors' data repository)
RODS = {38: 0.025, 66: 0.05, 76: 0.05, 100: 0.05, 200: 0.05}
LAB = ["--protocol", "lab", "--gravity", "9.81", "--freq", "5", "--amplitude", "0.025", "--fields-every", "0",
       "--quiet"]
#: the sets: what each run adds to LAB (alpha, length and seed come from the grid)
SETS = {
    # Fig. 1A-F: poured, container lifted (1 s), shaken 10 s (50 cycles); a sample per cycle
    "shake": dict(alphas=(38, 66, 76, 100, 200), seeds=(0, 1),
                  args=["--duration", "10", "--lift-duration", "1", "--save-every", "0.025", "--checkpoint-every", "1"]),
    # Fig. 2-3: poured, pressed to the CT's strains, each held; the fields at each
    "press": dict(alphas=(38, 66, 76, 100), seeds=(0, 1),
                  args=["--strains", "0,0.05,0.1,0.15", "--press-duration", "0.5", "--duration", "0",
                        "--lift-duration", "0.2", "--save-every", "0.05", "--checkpoint-every", "1"]),
    # causes of the CT differences (issue 48): the piston and the cylinder's wall frictionless
    "press-frictionless": dict(alphas=(38, 100), seeds=(0, 1),
                               args=["--strains", "0,0.05,0.1,0.15", "--press-duration", "0.5", "--duration", "0",
                                     "--lift-duration", "0.2", "--save-every", "0.05", "--checkpoint-every", "1",
                                     "--wall-mu", "0"]),
    # the CT's own container and fill (Materials and Methods, "Packing preparation" and "X-ray
    # Computerized Tomography imaging": 150 mm across, rods added to about 100 mm)
    "press-ct": dict(alphas=(100, 66, 76), seeds=(0,), container_m=0.075, fill_to_m=0.1,
                     args=["--strains", "0,0.05,0.1,0.15", "--press-duration", "0.5", "--duration", "0",
                           "--lift-duration", "0.2", "--save-every", "0.05", "--checkpoint-every", "0.5"]),
    # the pile's size at alpha 38, whose CT pile (150 mm across, 100 mm tall at l = 25 mm) would need
    # 30 000 rods: twice the press set's radius and height (6566 rods)
    "press-wide": dict(alphas=(38,), seeds=(0,), container_l=2.0, fill_l=2.0,
                       args=["--strains", "0,0.05,0.1,0.15", "--press-duration", "0.5", "--duration", "0",
                             "--lift-duration", "0.2", "--save-every", "0.05", "--checkpoint-every", "0.5"]),
    # container size: the shaking of alpha 38 and 66 in a cylinder 1.5 times as wide
    "container": dict(alphas=(38, 66), seeds=(0, 1),
                      args=["--container-radius", "1.5", "--duration", "10", "--lift-duration", "1",
                            "--save-every", "0.025", "--checkpoint-every", "1"]),
    # alpha 200 as rigid rods (the sag rule makes them elastic, at about 12 minutes of one core per simulated
    # second here; rigid rods hold worse, so a rigid packing that holds is a bound for the elastic one)
    "shake-rigid": dict(alphas=(200,), seeds=(0, 1),
                        args=["--duration", "10", "--lift-duration", "1", "--save-every", "0.025",
                              "--checkpoint-every", "1", "--rod-model", "rigid"]),
    # the lab's fill height: rods poured to about 100 mm (4 l at alpha 38, 2 l at l = 50 mm), then the
    # container lifted away (the test, 1.5 s); no shaking
    "tall": dict(alphas=(38, 100), seeds=(0, 1), fill_to_m=0.1,
                 args=["--duration", "0", "--lift-duration", "1.5", "--save-every", "0.05", "--checkpoint-every", "0.5"]),
}


def _name(kind: str, alpha: int, seed: int) -> str:
    return f"{kind}_alpha{alpha}_seed{seed}"


def _command(kind: str, alpha: int, seed: int, folder: Path) -> list[str]:
    spec = SETS[kind]
    fill = spec.get("fill_to_m")
    extra = ["--fill-height", f"{fill / RODS[alpha]:g}"] if fill else []
    if spec.get("container_m"):
        extra += ["--container-radius", f"{spec['container_m'] / RODS[alpha]:g}"]
    if spec.get("container_l"):
        extra += ["--container-radius", f"{spec['container_l']:g}", "--fill-height", f"{spec['fill_l']:g}"]
    return ["rodwarp", "simulate", *LAB, "--alpha", str(alpha), "--length", str(RODS[alpha]), "--seed", str(seed),
            *SETS[kind]["args"], *extra, "--out", str(folder)]


def _finished(folder: Path) -> bool:
    return (folder / "summary.json").exists()


def run(args) -> int:
    runs = Path(args.runs)
    runs.mkdir(parents=True, exist_ok=True)
    spec = SETS[args.set]
    alphas = [int(a) for a in args.alphas.split(",")] if args.alphas else spec["alphas"]
    seeds = [int(s) for s in args.seeds.split(",")] if args.seeds else spec["seeds"]
    exe = str(Path(sys.executable).with_name("rodwarp"))
    for seed in seeds:  # every alpha of a seed before the next seed: a stopped set still spans alpha
        for alpha in alphas:
            folder = runs / _name(args.set, alpha, seed)
            if _finished(folder):
                continue
            cmd = _command(args.set, alpha, seed, folder)
            cmd[0] = exe
            if any(folder.glob("checkpoints/ckpt_*.npz")):
                cmd.append("--resume")
            t0 = time.perf_counter()
            print(f"{datetime.now(timezone.utc):%H:%M:%S} {' '.join(shlex.quote(c) for c in cmd[1:])}", flush=True)
            rc = subprocess.run(cmd).returncode
            print(f"  -> exit {rc} after {time.perf_counter() - t0:.0f} s", flush=True)
            if rc != 0 and not args.keep_going:
                return rc
    return 0


# ----------------------------------------------------------------------------- report


def _runs(runs: Path, kind: str) -> list[dict]:
    out = []
    for d in sorted(runs.glob(f"{kind}_alpha*_seed*")):
        f = d / "summary.json"
        s = json.loads(f.read_text()) if f.exists() else _in_progress(d)
        if s is not None:
            out.append({"run": d.name, "alpha": int(round(s["alpha"])), "seed": s["seed"], "summary": s})
    return out


def _in_progress(folder: Path) -> dict | None:
    """What summary.json will hold of a shaking run still going (or killed), from its metrics.csv
    up to its last checkpoint: the lift and the shaking so far, ``incomplete`` with the seconds
    shaken. None before the shaking has begun."""
    import csv

    from rodwarp.experiments import ProtocolParams
    from rodwarp.experiments.protocols.lab import shake_result
    from rodwarp.experiments._params import rod_model_rule
    from rodwarp.experiments._verdict import DEFAULT_THRESHOLDS

    meta = json.loads((folder / "rodwarp-run.json").read_text())
    p = meta["parameters"]
    try:
        with open(folder / "metrics.csv") as fh:
            rows = list(csv.DictReader(fh))
    except FileNotFoundError:
        return None
    t_lifted = p["pour_duration"] + p["lift_duration"]
    if p["strains"] or not any(r["stage"] == "lift" and float(r["time"]) >= t_lifted - 1e-9 for r in rows):
        return None  # not yet through the lift
    params = ProtocolParams(**{**p, "box": tuple(p["box"]), "strains": ()})
    shaken = any(r["stage"] == "shake" and float(r["time"]) > t_lifted for r in rows)
    sh = shake_result(params, rows, t_lifted, DEFAULT_THRESHOLDS) if shaken else None
    lift = [r for r in rows if r["stage"] == "lift"]
    pour = [r for r in rows if r["stage"] == "pour"]
    rc = p["container_radius"] * p["length"]
    started = datetime.fromisoformat(meta["started"].replace("+0000", "+00:00"))
    return {"alpha": p["alpha"], "seed": p["seed"], "n_rods": params.rods, "length": p["length"],
            "diameter": params.diameter, "rod_model": rod_model_rule(params)["rod_model"],
            "contact_law": {"name": p["contact_law"] or "exact"}, "parameters": p,
            # to its last checkpoint (metrics.csv is written then), so a killed run's time stops growing
            "wall_time_s": (folder / "metrics.csv").stat().st_mtime - started.timestamp(),
            "incomplete": {"shaken_s": sh["shaken_s"] if sh else 0.0, "of_s": p["duration"], "status": meta["status"]},
            "persistence": None, "stable": None,
            "max_penetration_over_d": max(float(r["max_penetration_over_d"]) for r in rows),
            "lab": {"container_radius_m": rc, **({"shake": sh} if sh else {}),
                    "lift": {"height_kept_after_lift": float(lift[-1]["centroid_height"]) /
                             float(pour[-1]["centroid_height"]),
                             "spread_radius_m": float(lift[-1]["spread_radius"]),
                             "spread_over_container": float(lift[-1]["spread_radius"]) / rc,
                             "largest_cluster_fraction": float(lift[-1]["largest_cluster_fraction"]),
                             "kinetic_energy_J": float(lift[-1]["kinetic_energy"])}}}


def _paper_means(data: Path | None) -> tuple[dict, dict]:
    """(alpha, strain) -> the authors' fields' statistics: the means of n, phi, S, c over their
    valid voxels (n > 0), and the statistics of e and n (rodwarp.analysis.field_statistics) over
    the interior, the valid voxels at least one ball radius from an empty voxel or the grid's
    edge, where a ball lies wholly inside the packing as the simulated balls do."""
    from scipy import ndimage as ndi

    from rodwarp.analysis import field_statistics
    from rodwarp.analysis._fieldset import Fields

    if data is None:
        return {}, {}
    means, interior = {}, {}
    for f in sorted(Path(data).glob("alpha*_epsilon*.npz")):
        a, e = f.stem.replace("alpha", "").split("_epsilon")
        key = (int(a), int(e) / 100)
        fl = Fields.load(f)
        valid = fl.valid
        means[key] = {k: float(np.nanmean(np.asarray(fl.get(src))[valid]))
                      for k, src in (("mean_n", "n"), ("mean_phi", "phi"), ("mean_S", "S"), ("mean_c", "c"))}
        steps = int(round(fl.radius / fl.spacing))
        inner = ndi.binary_erosion(valid, iterations=steps, border_value=0)
        n = np.asarray(fl.get("n")).copy()
        n[~inner] = 0
        fl.n = n
        st = field_statistics(fl, power_laws=False)
        interior[key] = {k: st.get(k) for k in ("mean_n", "cv_e", "mean_e", "q1_e", "q3_e", "e_lb")}
        interior[key]["share_of_valid"] = float(inner.sum() / valid.sum())
    return means, interior


#: the fields whose distributions are compared with the authors' (their data's README: e and n the
#: most trustworthy; their S is the eigenvalue of largest magnitude, and their c has another
#: normalisation; docs/experiments.md says which compare)
DIST_FIELDS = ("e", "n", "phi", "S", "c")


def _quartiles(path: Path) -> dict:
    """Quartiles (q1, median, q3) and mean of each of DIST_FIELDS over the valid voxels of a
    field file (rodwarp's fields_press<E>.npz or the authors' npz)."""
    from rodwarp.analysis._fieldset import Fields

    f = Fields.load(path)
    v = f.valid
    out = {}
    for k in DIST_FIELDS:
        a = np.asarray(f.get(k))[v]
        a = a[np.isfinite(a)]
        if a.size:
            q1, med, q3 = np.quantile(a, [0.25, 0.5, 0.75])
            out[k] = {"mean": float(a.mean()), "q1": float(q1), "median": float(med), "q3": float(q3)}
    return out


def _distributions(runs: Path, press: list[dict], data: Path | None) -> list[dict]:
    """Per (alpha, strain): the quartiles of each field, simulated (every seed's file pooled as a
    list) beside the authors'."""
    out = []
    for r in press:
        for st in r["summary"]["lab"].get("strains", []):
            f = runs / r["run"] / f"fields_press{st['strain']:g}.npz"
            if not f.exists():
                continue
            exp = None
            if data is not None:
                e = Path(data) / f"alpha{r['alpha']}_epsilon{round(100 * st['strain']):02d}.npz"
                exp = _quartiles(e) if e.exists() else None
            out.append({"alpha": r["alpha"], "seed": r["seed"], "strain": st["strain"], "sim": _quartiles(f),
                        "exp": exp})
    return out


def _rel(sim, exp):
    return None if sim is None or exp in (None, 0) else (sim - exp) / exp


def report(args) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from rodwarp._util import versions

    runs = Path(args.runs)
    out = Path(args.out)
    shake, press, cont = _runs(runs, "shake"), _runs(runs, "press"), _runs(runs, "container")
    tall, rigid = _runs(runs, "tall"), _runs(runs, "shake-rigid")
    paper = {(int(f["alpha"]), float(f["epsilon"])): f
             for f in json.loads((OUT / "paper_fields.json").read_text())["files"]}
    paper_means, paper_interior = _paper_means(Path(args.paper_fields) if args.paper_fields else None)

    def row(r):
        s, lab = r["summary"], r["summary"]["lab"]
        out = {"run": r["run"], "alpha": r["alpha"], "seed": r["seed"], "n_rods": s["n_rods"],
               "incomplete": s.get("incomplete"),
               "length_m": s["length"], "diameter_m": s["diameter"], "rod_model": s["rod_model"],
               "container_radius_m": lab["container_radius_m"], "wall_time_s": s["wall_time_s"],
               "contact_law": s["contact_law"]["name"], "mu": s["parameters"]["mu"],
               "fill_height_m": s["parameters"]["fill_height"] * s["length"]}
        if "lift" in lab:
            out["lift"] = lab["lift"]
        if "shake" in lab:
            sh = lab["shake"]
            out.update(cycles=sh["cycles"], y_ratio=sh["centroid_height_ratio"], cohesion=sh["cohesion"],
                       landed_cycle=sh["landed"]["cycle"], landed_y_ratio=sh["landed"]["centroid_height_ratio"],
                       persistence_h_and_f=s["persistence"], stable=s["stable"], a_over_g=sh["a_over_g"],
                       max_penetration_over_d=s.get("max_penetration_over_d"))
        if lab.get("strains"):
            out["strains"] = lab["strains"]
        return out

    table = {"shake": [row(r) for r in shake], "press": [row(r) for r in press],
             "container": [row(r) for r in cont], "tall": [row(r) for r in tall],
             "shake_rigid": [row(r) for r in rigid]}
    # field statistics against strain beside the authors'
    compare = []
    keys = ("mean_n", "cv_e", "mean_e", "q1_e", "q3_e", "e_lb", "mean_phi", "mean_S", "mean_c")
    for r in table["press"]:
        for st in r.get("strains", []):
            exp = {**paper.get((r["alpha"], st["strain"]), {}), **paper_means.get((r["alpha"], st["strain"]), {})}
            inner = paper_interior.get((r["alpha"], st["strain"]), {})
            compare.append({"alpha": r["alpha"], "seed": r["seed"], "strain": st["strain"],
                            **{f"sim_{k}": st.get(k) for k in keys},
                            **{f"exp_{k}": exp.get(k) for k in keys},
                            **{f"rel_{k}": _rel(st.get(k), exp.get(k)) for k in keys},
                            **{f"expin_{k}": v for k, v in inner.items()},
                            **{f"relin_{k}": _rel(st.get(k), v) for k, v in inner.items() if k in keys}})
    # the command as run, its folders named without the machine's paths
    argv = [Path(a).name if i and sys.argv[i - 1] in ("--runs", "--paper-fields", "--out") else a
            for i, a in enumerate(sys.argv)]
    record = {"command": " ".join(shlex.quote(a) for a in ["python", "scripts/lab_experiments.py", *argv[1:]]), "date": datetime.now(timezone.utc).isoformat(),
              "versions": versions(), "sets": {k: v["args"] for k, v in SETS.items()}, "lab_args": LAB,
              "rods": {str(a): {"length_m": l, "diameter_m": l / a} for a, l in RODS.items()},
              "runs": table, "transition": {
                  "sag_rule": transition([r for r in table["shake"] if not r["incomplete"]]),
                  "rigid": transition([r for r in table["shake"] + table["shake_rigid"]
                                       if not r["incomplete"] and r["rod_model"] == "rigid"])}, "fields_vs_paper": compare,
              "same_span": same_span(runs, table["shake"] + table["shake_rigid"]),
              "field_distributions": _distributions(runs, press, Path(args.paper_fields) if args.paper_fields
                                                    else None)}
    out.mkdir(parents=True, exist_ok=True)
    (out / "lab_experiments.json").write_text(json.dumps(record, indent=1))

    figs = []
    if table["shake"]:
        fig, ax = plt.subplots(1, 2, figsize=(11, 4))
        colors = {a: f"C{i}" for i, a in enumerate(sorted(RODS))}
        seen = set()
        for r in sorted(table["shake"] + table["shake_rigid"], key=lambda r: (r["alpha"], r["rod_model"], r["seed"])):
            if "landed_cycle" not in r:  # not yet shaken
                continue
            key = (r["alpha"], r["rod_model"])
            label = None if key in seen else f"alpha {r['alpha']} ({r['rod_model']}" + (
                ", in progress)" if r["incomplete"] else ")")
            seen.add(key)
            ax[0].plot(r["landed_cycle"], r["landed_y_ratio"], color=colors.get(r["alpha"]), lw=1.5 if
                       r["rod_model"] == "elastic" else 1, ls=":" if r in table["shake_rigid"] else "-",
                       alpha=1.0 if r["seed"] == 0 else 0.55, label=label)
        ax[0].set(xlabel="cycles N = t f", ylabel="y_c / y_c(0), landed (lowest of each cycle)",
                  title="Fig. 1E in silico (5 Hz, 25 mm; seed 1 paler)", ylim=(0, None))
        ax[0].legend(fontsize=8)
        for rows, style, label in (
                ([r for r in table["shake"] if not r["incomplete"]], "o-", "sag rule's rod model (median of seeds)"),
                ([r for r in table["shake"] + table["shake_rigid"] if not r["incomplete"] and
                  r["rod_model"] == "rigid"], "s--", "rigid rods at every alpha")):
            by = {}
            for r in rows:
                by.setdefault(r["alpha"], []).append(r["cohesion"]["persistence"])
            al = sorted(by)
            if al:
                ax[1].plot(al, [np.median(by[a]) for a in al], style, mfc="none", label=label)
                for a in al:
                    ax[1].plot([a] * len(by[a]), by[a], "k.", alpha=0.5)
        going = [r for r in table["shake"] + table["shake_rigid"] if r["incomplete"] and "cohesion" in r]
        for r in going:
            ax[1].plot(r["alpha"], r["cohesion"]["persistence"], "x", color="C3")
        if going:
            ax[1].plot([], [], "x", color="C3", label="runs in progress: tau_f of the shaking so far ("
                       + ", ".join(f"{r['incomplete']['shaken_s']:.1f}" for r in going) + " s)")
        ax[1].axvline(100, color="r", ls="--", label="paper's experiments (~100)")
        ax[1].axvline(35, color="gray", ls=":", label="rodwarp, paper's numerical protocol (35)")
        tr = (record["transition"]["sag_rule"] or record["transition"]["rigid"]).get("tau_f", {})
        if tr.get("alpha_star"):
            ax[1].axvline(tr["alpha_star"], color="C0", ls="-.", label=f"in silico lab: {tr['alpha_star']:.0f}")
        ax[1].set(xscale="log", xlabel="alpha", ylabel="tau_f (share of the shaking in one cluster)",
                  title="Fig. 1F in silico", ylim=(-0.05, 1.05))
        ax[1].legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "lab_shake.png", dpi=120)
        figs.append("lab_shake.png")
        plt.close(fig)
    lifted = [r for r in table["shake"] + table["shake_rigid"] + table["tall"] if "lift" in r]
    if lifted:
        fig, ax = plt.subplots(figsize=(5.5, 4))
        for r in lifted:
            full = r in table["tall"]
            el = r["rod_model"] == "elastic"
            ax.plot(r["alpha"], r["lift"]["height_kept_after_lift"], "D" if el else "o", color="C0",
                    mfc="none" if full else "C0")
            ax.plot(r["alpha"], r["lift"]["spread_over_container"], "P" if el else "s", color="C1",
                    mfc="none" if full else "C1")
        if any(r["rod_model"] == "elastic" for r in lifted):
            ax.plot([], [], "D", color="k", label="diamond, plus: elastic rods (else rigid)")
        ax.plot([], [], "o", color="C0", label="centroid height after / before the lift")
        ax.plot([], [], "s", color="C1", label="spread radius / container radius")
        if table["tall"]:
            ax.plot([], [], "o", color="k", mfc="none", label="open: filled to 100 mm, as in the lab")
        ax.set(xscale="log", xlabel="alpha", title="The container lifted away (Fig. 1A-B)")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(out / "lab_lift.png", dpi=120)
        figs.append("lab_lift.png")
        plt.close(fig)
    if compare:
        stats = [("mean_n", "mean n"), ("cv_e", "cv_e"), ("mean_e", "mean e"), ("e_lb", "e_lb")]
        fig, axs = plt.subplots(1, len(stats), figsize=(4 * len(stats), 3.6))
        for ax, (k, label) in zip(axs, stats):
            for i, a in enumerate(sorted({c["alpha"] for c in compare})):
                cs = [c for c in compare if c["alpha"] == a]
                eps = sorted({c["strain"] for c in cs})
                sim = [np.median([c[f"sim_{k}"] for c in cs if c["strain"] == e and c[f"sim_{k}"] is not None] or
                                 [np.nan]) for e in eps]
                exp = [next((c[f"exp_{k}"] for c in cs if c["strain"] == e), None) for e in eps]
                ax.plot(eps, sim, "o-", color=f"C{i}", label=f"alpha {a} sim")
                ax.plot(eps, [np.nan if v is None else v for v in exp], "x--", color=f"C{i}", label=f"alpha {a} CT")
            ax.set(xlabel="strain epsilon", title=label)
        axs[0].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out / "lab_fields_vs_strain.png", dpi=120)
        figs.append("lab_fields_vs_strain.png")
        plt.close(fig)
    _write_md(out / "lab_experiments.md", record, figs)
    print(f"wrote {out / 'lab_experiments.json'}, lab_experiments.md and {', '.join(figs) or 'no figures'}")
    return 0


def transition(shake: list[dict]) -> dict:
    """alpha* of the shaken packings, three ways: the seed mean of tau_f, of the cohesive verdict
    and of f at the end (the paper's f >= 0.5) crossing 1/2, interpolated in log alpha between the
    bracketing alphas, with a bootstrap over seeds (rodwarp.experiments._phase, as the sweeps')."""
    import random

    from rodwarp.experiments._phase import _bracketed

    by: dict = {}
    for r in shake:
        by.setdefault(r["alpha"], []).append(r)
    if len(by) < 2:
        return {}
    alphas = sorted(by)
    out = {}
    for key, value in (("tau_f", lambda r: r["cohesion"]["persistence"]),
                       ("cohesive", lambda r: float(r["cohesion"]["cohesive"])),
                       ("f_end", lambda r: r["cohesion"]["largest_cluster_fraction"])):
        x, err, lo, hi, boot, note = _bracketed(alphas, by, value, random.Random(0), 200)
        out[key] = {"alpha_star": x, "bracket_lo": lo, "bracket_hi": hi, "boot_std": boot, "note": note,
                    "seed_mean": {str(a): float(np.mean([value(r) for r in by[a]])) for a in alphas},
                    "seeds": {str(a): len(by[a]) for a in alphas}}
    return out


def same_span(runs: Path, rows: list[dict]) -> dict:
    """The runs still shaking beside the finished ones over the same span: X = the shortest
    shaking of a run in progress (s); for every shaken run, f at X, tau_f over [0, X] and the
    landed y_c / y_c(0) of the last whole cycle within X, from its metrics.csv."""
    import csv

    from rodwarp.experiments._verdict import DEFAULT_THRESHOLDS, persistence

    going = [r for r in rows if r["incomplete"] and "cohesion" in r]
    if not going:
        return {}
    span = min(r["incomplete"]["shaken_s"] for r in going)
    out = []
    for r in rows:
        if "cohesion" not in r:
            continue
        with open(runs / r["run"] / "metrics.csv") as fh:
            sh = [x for x in csv.DictReader(fh) if x["stage"] == "shake"]
        p = json.loads((runs / r["run"] / "rodwarp-run.json").read_text())["parameters"]
        t0 = p["pour_duration"] + p["lift_duration"]
        keep = [x for x in sh if t0 < float(x["time"]) <= t0 + span + 1e-9]
        t = np.array([float(x["time"]) for x in keep])
        f = np.array([float(x["largest_cluster_fraction"]) for x in keep])
        n_cyc = int(np.floor(span * p["freq"] + 1e-9))
        y = [v for k, v in zip(r["landed_cycle"], r["landed_y_ratio"]) if k <= n_cyc]
        out.append({"run": r["run"], "alpha": r["alpha"], "seed": r["seed"], "rod_model": r["rod_model"],
                    "f": float(f[-1]), "tau_f": persistence(t, t0, f >= DEFAULT_THRESHOLDS.cluster),
                    "landed_y_ratio": y[-1] if y else None, "cycles": n_cyc, "in_progress": bool(r["incomplete"])})
    return {"span_s": span, "runs": out}


def _fmt(v, nd=3):
    if v is None:
        return "-"
    if isinstance(v, float):
        return f"{v:.{nd}g}"
    return str(v)


def _write_md(path: Path, record: dict, figs: list[str]) -> None:
    L = ["# The laboratory experiments in silico", "",
         f"Written by `scripts/lab_experiments.py report` on {record['date'][:10]} (rodwarp "
         f"{record['versions'].get('rodwarp')}, Warp {record['versions'].get('warp')}); docs/experiments.md says "
         "what was run and how it compares with the paper.", ""]
    sh = record["runs"]["shake"] + record["runs"]["shake_rigid"]
    if sh:
        L += ["## Shaking at 5 Hz, 25 mm and the lifted container", "",
              "| run | rods | model | law (mu) | Rc (mm) | lifted: h after/before | spread / Rc | tau_f | f end | "
              "cohesive | tau (h and f) | wall (s) |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in sorted(sh, key=lambda r: (r["alpha"], r["seed"])):
            c, lf = r.get("cohesion", {}), r.get("lift", {})
            inc = r.get("incomplete")
            name = r["run"] + (f" (in progress: {inc['shaken_s']:.3g} of {inc['of_s']:g} s shaken)" if inc else "")
            L.append(f"| {name} | {r['n_rods']} | {r['rod_model']} | {r['contact_law']} ({r['mu']:g}) | "
                     f"{r['container_radius_m'] * 1e3:.0f} | "
                     f"{_fmt(lf.get('height_kept_after_lift'))} | {_fmt(lf.get('spread_over_container'))} | "
                     f"{_fmt(c.get('persistence'))} | {_fmt(c.get('largest_cluster_fraction'))} | "
                     f"{c.get('cohesive', '-')} | {_fmt(r.get('persistence_h_and_f'))} | {r['wall_time_s']:.0f} |")
        L.append("")
    for which, tr in (record.get("transition") or {}).items():
        if not tr:
            continue
        title = {"sag_rule": "the sag rule's rod models (elastic at alpha 200)", "rigid": "rigid rods at every alpha"}
        L += [f"## The transition in the shaken packings: {title[which]}", "",
              "Finished runs only. Seed means per alpha, and alpha* where they cross 1/2 (interpolated in log "
              "alpha; bracket; bootstrap over seeds). The paper's experiments put the transition near alpha 100; "
              "rodwarp on the paper's numerical protocol, 35 (25-50) (docs/transition.md).", "",
              "| measure | " + " | ".join(f"alpha {a}" for a in tr["tau_f"]["seed_mean"]) + " | alpha* | bracket |",
              "|---" * (3 + len(tr["tau_f"]["seed_mean"])) + "|"]
        names = {"tau_f": "tau_f (share of the shaking with f >= 0.8)", "cohesive": "cohesive (share of seeds)",
                 "f_end": "f at the end (paper: f >= 0.5)"}
        for k, v in tr.items():
            star = v["note"] if v["alpha_star"] is None else f"{v['alpha_star']:.0f}"
            if v["alpha_star"] is not None and v["boot_std"] is not None:
                star += f" (bootstrap {v['boot_std']:.0f})"
            br = f"{_fmt(v['bracket_lo'])}-{_fmt(v['bracket_hi'])}" if v["bracket_lo"] and v["bracket_hi"] else "-"
            L.append(f"| {names[k]} | " + " | ".join(f"{m:.2f}" for m in v["seed_mean"].values())
                     + f" | {star} | {br} |")
        L.append("")
    ss = record.get("same_span") or {}
    if ss:
        L += [f"## Every shaken run over the first {ss['span_s']:.1f} s ({ss['runs'][0]['cycles']} cycles), the "
              "span the runs in progress have reached", "",
              "| run | model | f at that time | tau_f over it | landed y_c / y_c(0), last whole cycle |",
              "|---|---|---|---|---|"]
        for r in sorted(ss["runs"], key=lambda r: (r["alpha"], r["rod_model"], r["seed"])):
            L.append(f"| {r['run']}{' (in progress)' if r['in_progress'] else ''} | {r['rod_model']} | "
                     f"{_fmt(r['f'])} | {_fmt(r['tau_f'])} | {_fmt(r['landed_y_ratio'])} |")
        L.append("")
    tl = record["runs"].get("tall") or []
    if tl:
        L += ["## The lifted container at the lab's fill height (about 100 mm)", "",
              "| run | rods | fill height (mm) | Rc (mm) | h after/before | spread / Rc | f | kinetic energy (J) | "
              "wall (s) |", "|---|---|---|---|---|---|---|---|---|"]
        for r in sorted(tl, key=lambda r: (r["alpha"], r["seed"])):
            lf = r["lift"]
            L.append(f"| {r['run']} | {r['n_rods']} | {r['fill_height_m'] * 1e3:.0f} | "
                     f"{r['container_radius_m'] * 1e3:.0f} | {_fmt(lf['height_kept_after_lift'])} | "
                     f"{_fmt(lf['spread_over_container'])} | {_fmt(lf['largest_cluster_fraction'])} | "
                     f"{_fmt(lf['kinetic_energy_J'], 2)} | {r['wall_time_s']:.0f} |")
        L.append("")
    ct = record["runs"]["container"]
    if ct:
        L += ["## Container size", "", "| run | rods | Rc (mm) | spread / Rc | tau_f | f end | wall (s) |",
              "|---|---|---|---|---|---|---|"]
        for r in sorted(ct + [s for s in sh if s["alpha"] in {c["alpha"] for c in ct}],
                        key=lambda r: (r["alpha"], r["container_radius_m"], r["seed"])):
            L.append(f"| {r['run']} | {r['n_rods']} | {r['container_radius_m'] * 1e3:.0f} | "
                     f"{_fmt(r.get('lift', {}).get('spread_over_container'))} | {_fmt(r['cohesion']['persistence'])} | "
                     f"{_fmt(r['cohesion']['largest_cluster_fraction'])} | {r['wall_time_s']:.0f} |")
        L.append("")
    cmp_ = record["fields_vs_paper"]
    if cmp_:
        keys = ("mean_n", "cv_e", "mean_e", "q1_e", "q3_e", "e_lb", "mean_phi", "mean_S", "mean_c")
        L += ["## Fields of the pressed packings against the authors' CT fields", "",
              "Each cell: simulated / experimental (relative difference). Ball radius sqrt(d l) on both sides.", "",
              "| alpha | seed | strain | " + " | ".join(keys) + " |", "|---" * (3 + len(keys)) + "|"]
        for c in sorted(cmp_, key=lambda c: (c["alpha"], c["strain"], c["seed"])):
            cells = []
            for k in keys:
                s, e, r = c[f"sim_{k}"], c[f"exp_{k}"], c[f"rel_{k}"]
                cells.append(f"{_fmt(s)} / {_fmt(e)} ({'-' if r is None else f'{r:+.0%}'})")
            L.append(f"| {c['alpha']} | {c['seed']} | {c['strain']:g} | " + " | ".join(cells) + " |")
        L.append("")
        inner = ("mean_n", "cv_e", "mean_e", "q1_e", "q3_e", "e_lb")
        if any(c.get("expin_mean_e") is not None for c in cmp_):
            L += ["### Against the interior of the CT fields", "",
                  "The simulated balls lie wholly inside the packing (the box inscribed in the cylinder, from the "
                  "plate to the piston); the authors' statistics count every voxel with a rod in its ball, the "
                  "packing's surface included. Here the CT side keeps only the voxels at least one ball radius "
                  "from an empty voxel or the grid's edge (share of their valid voxels in the last column). "
                  "Each cell: simulated / CT interior (relative difference).", "",
                  "| alpha | seed | strain | " + " | ".join(inner) + " | CT share |", "|---" * (4 + len(inner)) + "|"]
            for c in sorted(cmp_, key=lambda c: (c["alpha"], c["strain"], c["seed"])):
                cells = []
                for k in inner:
                    s, e, r = c[f"sim_{k}"], c.get(f"expin_{k}"), c.get(f"relin_{k}")
                    cells.append(f"{_fmt(s)} / {_fmt(e)} ({'-' if r is None else f'{r:+.0%}'})")
                L.append(f"| {c['alpha']} | {c['seed']} | {c['strain']:g} | " + " | ".join(cells)
                         + f" | {_fmt(c.get('expin_share_of_valid'), 2)} |")
            L.append("")
    dist = record.get("field_distributions") or []
    if dist:
        L += ["## Distributions of the fields: quartiles q1 / median / q3", "",
              "Simulated (seeds pooled: the median of the seeds' quartiles) and the authors' CT fields, valid voxels "
              "(n > 0). e, n and phi compare; the authors' S is the eigenvalue of largest magnitude and their c "
              "has another normalisation (docs/experiments.md).", "",
              "| alpha | strain | " + " | ".join(f"{k} sim | {k} CT" for k in DIST_FIELDS) + " |",
              "|---" * (2 + 2 * len(DIST_FIELDS)) + "|"]
        keys = sorted({(d["alpha"], d["strain"]) for d in dist})
        for a, e in keys:
            ds = [d for d in dist if (d["alpha"], d["strain"]) == (a, e)]
            cells = []
            for k in DIST_FIELDS:
                sim = [d["sim"][k] for d in ds if k in d["sim"]]
                q = "/".join(_fmt(float(np.median([x[j] for x in sim]))) for j in ("q1", "median", "q3")) \
                    if sim else "-"
                ex = ds[0]["exp"].get(k) if ds[0]["exp"] else None
                cells += [q, "/".join(_fmt(ex[j]) for j in ("q1", "median", "q3")) if ex else "-"]
            L.append(f"| {a} | {e:g} | " + " | ".join(cells) + " |")
        L.append("")
    L += [f"![{f}]({f})" for f in figs]
    path.write_text("\n".join(L) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    r = sub.add_parser("run", help="make the unfinished runs of a set")
    r.add_argument("--set", choices=sorted(SETS), required=True)
    r.add_argument("--runs", required=True, help="folder of the run folders (outside the repository)")
    r.add_argument("--alphas", help="comma-separated subset of the set's aspect ratios")
    r.add_argument("--seeds", help="comma-separated seeds (default the set's)")
    r.add_argument("--keep-going", action="store_true", help="go on after a failed run")
    p = sub.add_parser("report", help="collect the finished runs into benchmarks/results")
    p.add_argument("--runs", required=True)
    p.add_argument("--paper-fields", help="folder of the authors' alpha*_epsilon*.npz fields (for mean n, phi, S, c)")
    p.add_argument("--out", default=str(OUT))
    args = ap.parse_args(argv)
    return run(args) if args.what == "run" else report(args)


if __name__ == "__main__":
    sys.exit(main())
