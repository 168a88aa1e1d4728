"""`rodwarp sweep` machinery (issue 7): Dask LocalCluster runs, resume, failures, phase diagram."""

from __future__ import annotations

import csv
import json
import math

import pytest

pytest.importorskip("distributed")

from rodwarp.experiments import SweepSpec, alpha_star, phase_diagram, points, read_results, run_point, run_sweep  # noqa: E402

TINY = {"n_rods": 12, "save_every": 0.01, "checkpoint_every": 0.01}


def _spec(**kw):
    base = dict(alphas=[20, 30], freqs=[1, 10], entangle_duration=0.02, duration=0.02, overrides=dict(TINY),
                device="cpu")
    base.update(kw)
    return SweepSpec(**base)


def test_points_grid_and_ids():
    spec = _spec(gravities=[0.5, 2], seeds=[0, 1])
    pts = points(spec)
    assert len(pts) == 2 * 2 * 2 * 2
    ids = [p["id"] for p in pts]
    assert len(set(ids)) == len(ids)
    assert ids == [p["id"] for p in points(spec)]  # stable
    assert "alpha30_freq1_g0.5_F0_seed0" in ids
    assert all(p["n_rods"] == 12 and p["_analyze"] == {} for p in pts)


def test_spec_rejects_bad_overrides():
    from rodwarp.errors import RodwarpError

    with pytest.raises(RodwarpError, match="unknown simulate"):
        points(_spec(overrides={"nope": 1}))
    with pytest.raises(RodwarpError, match="set by the sweep"):
        points(_spec(overrides={"alpha": 3}))


def test_run_point_records_failure(tmp_path):
    p = {**points(_spec(alphas=[20], freqs=[1]))[0], "alpha": 0.5}  # a point past the grid's check: alpha must be > 1
    row = run_point(p, str(tmp_path / p["id"]))
    assert row["status"].startswith("error:") and "alpha" in row["status"]
    assert row["alpha"] == 0.5 and row["worker"] and row["wall_s"] >= 0


def test_sweep_local_cluster_resume_and_failure(tmp_path):
    out = tmp_path / "sw"
    spec = _spec()
    path = run_sweep(spec, out, workers=2, progress=False)
    rows = read_results(path)
    assert len(rows) == 4
    assert [r["status"] for r in rows] == ["ok"] * 4, rows
    for r in rows:
        assert 0 < float(r["largest_cluster_fraction"]) <= 1
        assert float(r["contacts_per_rod"]) >= 0
        assert r["stable"] in ("True", "False")
        assert float(r["height_kept"]) > 0 and 0 <= float(r["persistence"]) <= 1 and 0 <= float(r["rods_left"]) <= 1
        if r["stable"] == "True":  # the verdict's rule, read back from the row
            assert float(r["persistence"]) >= 0.5 and float(r["largest_cluster_fraction"]) >= 0.5
        assert r["cv_e"] != ""
        ag = 4 * math.pi**2 * float(r["freq"]) ** 2 * float(r["amplitude"]) / float(r["gravity"])
        assert math.isclose(float(r["a_over_g"]), ag, rel_tol=1e-9)
        assert r["F_tilde"] == r["static_load"]
        assert (out / "points" / r["id"] / "summary.json").exists()
        assert (out / "points" / r["id"] / "analysis" / "summary.json").exists()
    workers = {r["worker"] for r in rows}
    assert len(workers) >= 1 and all(":" in w for w in workers)
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["submitted"] == 4 and meta["skipped"] == 0 and meta["failed"] == 0
    assert meta["spec"]["alphas"] == [20, 30] and "distributed" in meta["versions"]

    # second run: nothing redone, rows untouched
    run_sweep(spec, out, workers=2, progress=False)
    again = read_results(path)
    assert again == rows
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["submitted"] == 0 and meta["skipped"] == 4

    # a grid with a value out of its range (alpha 1), or with an invalid point (a/g 7.9e4 at
    # 1000 Hz), is refused before any cluster starts: nothing run
    from rodwarp.errors import RodwarpError

    with pytest.raises(RodwarpError, match=r"--alpha must be > 1 and <= 10000, got 1"):
        run_sweep(_spec(alphas=[1, 20, 30], freqs=[1, 10]), out, workers=2, progress=False)
    with pytest.raises(RodwarpError, match=r"sweep point alpha30_freq1000_g0.5_F0_seed0 is invalid .*a/g = 7.9e\+04.*invalid points: 2 of 4"):
        run_sweep(_spec(alphas=[20, 30], freqs=[1, 1000]), out, workers=2, progress=False)
    assert read_results(path) == rows
    assert json.loads((out / "sweep.json").read_text())["skipped"] == 4

    # a larger grid in the same directory: the new points fail at run time (12 rods of alpha 3
    # do not fit the box), the others finish; the four finished points are not redone
    spec2 = _spec(alphas=[3, 20, 30], freqs=[1, 10])
    run_sweep(spec2, out, workers=2, progress=False)
    rows2 = {r["id"]: r for r in read_results(path)}
    assert len(rows2) == 6
    for r in rows:
        assert rows2[r["id"]] == r
    bad = [r for r in rows2.values() if r["status"] != "ok"]
    assert len(bad) == 2 and all(float(r["alpha"]) == 3 for r in bad)
    assert all("placed only" in r["status"] for r in bad)
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["submitted"] == 2 and meta["skipped"] == 4 and meta["failed"] == 2
    assert meta["first_failure"].startswith("alpha3_freq")


def _synthetic(out):
    rows = []
    for ag, freq in ((0.079, 1.0), (7.9, 10.0), (790.0, 100.0)):
        for a in (25, 50, 100, 200, 300):
            for seed in (0, 1):
                f = 1 / (1 + (100 / a) ** 3) + 0.02 * seed
                cv = 1.4 if f >= 0.5 else 0.8
                # the verdict: alpha 25 and 50 collapse; alpha 100 holds for seed 1 only
                stable = a > 100 or (a == 100 and seed == 1)
                rows.append({"id": f"a{a}_f{freq}_s{seed}", "alpha": a, "freq": freq, "gravity": 0.5,
                             "static_load": 0.0, "seed": seed, "amplitude": 0.001, "a_over_g": ag,
                             "largest_cluster_fraction": f, "contacts_per_rod": 3.0, "cv_e": cv,
                             "height_kept": 0.9 if stable else 0.3, "persistence": 1.0 if stable else 0.1,
                             "rods_left": 0.0, "stable": stable, "status": "ok"})
    rows.append({"id": "broken", "alpha": 25, "freq": 1.0, "status": "error: something"})
    keys = list(rows[0])
    with open(out / "results.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)


def test_phase_diagram_from_synthetic(tmp_path):
    _synthetic(tmp_path)
    written = phase_diagram(tmp_path)
    names = {p.name for p in written}
    assert {"phase_cv_e.png", "phase_f_alpha.png", "phase_f_ag.png", "alpha_star.csv",
            "phase_alpha_star.png", "phase_verdict_alpha.png"} <= names
    for p in written:
        assert p.stat().st_size > 1000 or p.suffix == ".csv"
    table = list(csv.DictReader(open(tmp_path / "alpha_star.csv")))
    assert len(table) == 3
    for t in table:
        a = float(t["alpha_star_f"])
        assert 50 < a < 110  # f = 0.5 at alpha = 100 (seed 0), slightly lower on the seed mean
        assert float(t["bracket_lo_f"]) == 50 and float(t["bracket_hi_f"]) == 100 and float(t["err_f"]) == 25
        assert t["boot_std_f"] != ""
        # the verdict: half the seeds stable at alpha 100, all at 200: alpha* = 100 exactly
        assert float(t["alpha_star"]) == pytest.approx(100.0)
        assert float(t["bracket_lo"]) == 50 and float(t["bracket_hi"]) == 100


def test_static_loads_give_alpha_star_per_load_and_its_figure(tmp_path):
    """A load that brings down half the alpha-50 seeds moves alpha* up, from between 25 and 50 to 50."""
    rows = []
    for F in (0.0, 5.0):
        for a in (25, 50, 100):
            for seed in (0, 1):
                stable = a == 100 or (a == 50 and (F == 0.0 or seed == 1))
                rows.append({"id": f"a{a}_F{F}_s{seed}", "alpha": a, "freq": 10.0, "gravity": 0.5, "static_load": F,
                             "seed": seed, "amplitude": 0.001, "a_over_g": 7.9, "largest_cluster_fraction": 0.9,
                             "contacts_per_rod": 3.0, "cv_e": 1.0, "height_kept": 0.5 if stable else 0.1,
                             "persistence": 1.0 if stable else 0.3, "rods_left": 0.0, "stable": stable, "status": "ok"})
    with open(tmp_path / "results.csv", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    names = {p.name for p in phase_diagram(tmp_path)}
    assert "phase_alpha_star_load.png" in names
    assert (tmp_path / "phase_alpha_star_load.png").stat().st_size > 1000
    table = {float(t["static_load"]): t for t in csv.DictReader(open(tmp_path / "alpha_star.csv"))}
    # no load: every alpha 50 stands, alpha 25 falls: alpha* between them
    assert float(table[0.0]["bracket_lo"]) == 25 and float(table[0.0]["bracket_hi"]) == 50
    # F~ = 5: half the alpha-50 seeds stand: alpha* = 50 exactly, bracketed by 25 and 100
    assert float(table[5.0]["alpha_star"]) == pytest.approx(50.0)


def test_alpha_star_bounds():
    rows = [{"alpha": a, "ag": 1.0, "gravity": 0.5, "static_load": 0.0, "largest_cluster_fraction": 0.9,
             "stable": True} for a in (25, 50)]
    t = alpha_star(rows)[0]
    assert t["alpha_star"] is None and t["bracket_hi"] == 25 and "below" in t["note"]
    assert t["alpha_star_f"] is None and t["bracket_hi_f"] == 25 and "below" in t["note_f"]


def test_sweep_command_exits_non_zero_when_a_point_fails(tmp_path):
    # one point, alpha 3 (16 rods that do not fit the box): fails at run time; with or without
    # figures the command exits 4 and names the failed point
    from typer.testing import CliRunner

    from rodwarp.cli import app

    out = tmp_path / "sw"
    res = CliRunner().invoke(app, ["sweep", "--alpha", "3", "--freq", "1", "--entangle-duration", "0.02", "--duration",
                                   "0.02", "--save-every", "0.01", "--workers", "1", "--device", "cpu", "--no-figures",
                                   "--quiet", "--out", str(out)])
    assert res.exit_code == 4, res.output
    err = [ln for ln in res.output.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "1 of 1 sweep points failed" in err[0] and "alpha3_freq1_g0.5_F0_seed0" in err[0]
    assert read_results(out / "results.csv")[0]["status"].startswith("error: placed only")


def test_local_cluster_serves_no_http(tmp_path):
    # distributed starts an HTTP server (/metrics, /health, /info) on the scheduler and on every
    # worker even without a dashboard; the sweep's local cluster stops them, so every port the
    # cluster's processes listen on speaks Dask's protocol only
    import socket

    import psutil

    from rodwarp.experiments._sweep import _local_cluster

    cluster, client = _local_cluster(1)
    try:
        me = psutil.Process()
        ports = {c.laddr.port for p in [me, *me.children(recursive=True)] for c in p.net_connections(kind="tcp")
                 if c.status == psutil.CONN_LISTEN}
        assert ports  # the scheduler, nanny and worker comms
        for port in ports:
            with socket.create_connection(("127.0.0.1", port), timeout=5) as s:
                s.settimeout(2)
                s.sendall(b"GET /health HTTP/1.0\r\nHost: localhost\r\n\r\n")
                try:
                    reply = s.recv(16)
                except (socket.timeout, ConnectionError):
                    reply = b""
            assert not reply.startswith(b"HTTP/"), f"port {port} answers HTTP"
        assert client.submit(lambda x: x + 1, 1).result() == 2  # the cluster still works
    finally:
        client.close()
        cluster.close()


def test_phase_diagram_draws_the_points_time_series_and_distributions(tmp_path):
    """From each point's own files: Z(t), f(t), cv_e(t) per alpha, and p(e), p(c) per alpha
    pooled over seeds with the fitted power law (power_law.csv), whose exponent is that of
    the synthetic fields (e ~ x^-1.5 on [1, 100])."""
    import numpy as np

    from rodwarp.analysis import Fields

    _synthetic(tmp_path)
    rng = np.random.default_rng(0)
    rows = [r for r in csv.DictReader(open(tmp_path / "results.csv")) if r["status"] == "ok"]
    for r in rows:
        d = tmp_path / "points" / r["id"]
        (d / "analysis").mkdir(parents=True)
        with open(d / "metrics.csv", "w", newline="") as fh:
            w = csv.DictWriter(fh, fieldnames=["time", "stage", "contacts_per_rod", "largest_cluster_fraction",
                                               "cv_e"])
            w.writeheader()
            for k in range(11):
                w.writerow({"time": 0.1 * k, "stage": "entangle" if k < 5 else "stability",
                            "contacts_per_rod": 3.0, "largest_cluster_fraction": 0.9,
                            "cv_e": 1.0 + 0.01 * k if k % 5 == 0 else ""})
        u = rng.random((8, 8, 8))
        e = ((100 ** -0.5 - 1) * u + 1) ** (1 / -0.5)  # p(e) ~ e^-1.5 on [1, 100]
        ax = np.arange(8) * 0.1
        Fields(phi=0.1 + 0 * e, S=0 * e, c=1.0 + 4 * u, e=e, n=1.0 + 0 * e, x=ax, y=ax, z=ax, radius=0.2,
               spacing=0.1).save(d / "analysis" / "fields.zarr")
    names = {p.name for p in phase_diagram(tmp_path)}
    groups = {(r["freq"], r["gravity"], r["static_load"]) for r in rows}
    assert len([n for n in names if n.startswith("phase_timeseries")]) == len(groups)
    assert len([n for n in names if n.startswith("phase_distributions")]) == len(groups)
    table = list(csv.DictReader(open(tmp_path / "power_law.csv")))
    fits = [t for t in table if t["field"] == "e"]
    assert fits and all(abs(float(t["gamma"]) - 1.5) < 0.15 for t in fits)


def test_sweep_set_reads_each_value_as_its_parameter_type():
    from rodwarp.cli import _overrides
    from rodwarp.errors import RodwarpError

    got = _overrides(["rod_model=rigid", "rolling=false", "iterations=6", "step-safety=0.5", "dt=none",
                      "box=2,2,2.5"])
    assert got == {"rod_model": "rigid", "rolling": False, "iterations": 6, "step_safety": 0.5, "dt": None,
                   "box": (2.0, 2.0, 2.5)}
    assert type(got["iterations"]) is int and type(got["step_safety"]) is float
    for bad, msg in (("rod_modl=rigid", "no such simulate parameter"), ("rolling=maybe", "not a valid bool"),
                     ("iterations=six", "not a valid int"), ("iterations", "needs KEY=VALUE"),
                     ("box=2,2", "three positive numbers")):
        with pytest.raises(RodwarpError, match=msg):
            _overrides([bad])
    # the overrides reach every point of the grid
    spec = SweepSpec(alphas=[25.0], freqs=[10.0], seeds=[0, 1], overrides=got)
    assert all(p["rod_model"] == "rigid" and p["rolling"] is False for p in points(spec))


def test_shared_entangling_gives_the_rows_of_separate_runs(tmp_path):
    """Points that differ only in the test frequency share their donor's entangled packing:
    the same results as each point entangling on its own, the donor named in the row."""
    from rodwarp.experiments import entangling_groups

    spec = _spec(alphas=[20], freqs=[1, 10, 30], gravities=[0.5, 2])
    groups = entangling_groups(points(spec))
    assert [[p["freq"] for p in g] for g in groups] == [[1.0, 10.0, 30.0]] * 2
    assert {p["gravity"] for p in groups[0]} == {0.5} and {p["gravity"] for p in groups[1]} == {2.0}

    shared = {r["id"]: r for r in read_results(run_sweep(spec, tmp_path / "shared", workers=2, progress=False))}
    spec_own = _spec(alphas=[20], freqs=[1, 10, 30], gravities=[0.5, 2], share_entangling=False)
    own = {r["id"]: r for r in read_results(run_sweep(spec_own, tmp_path / "own", workers=2, progress=False))}
    assert shared.keys() == own.keys() and len(own) == 6
    for pid, r in shared.items():
        assert r["status"] == "ok" and own[pid]["status"] == "ok"
        for k in ("largest_cluster_fraction", "height_kept", "persistence", "contacts_per_rod", "cv_e", "stable",
                  "max_penetration_over_d"):
            assert r[k] == own[pid][k], (pid, k)
        assert own[pid]["entangled_from"] == ""
        donor = f"alpha20_freq1_g{float(r['gravity']):g}_F0_seed0"
        assert r["entangled_from"] == ("" if pid == donor else donor)


def test_submission_order_and_dependencies(tmp_path):
    """Largest alpha first, each donor before its group's other points, which get the donor's
    future as an argument; Dask priorities follow that order (ties would be broken by Dask)."""
    from pathlib import Path

    from rodwarp.experiments._sweep import _submit

    class Client:
        def __init__(self):
            self.calls = []

        def submit(self, fn, *args, priority=None, **kw):
            fut = f"fut-{args[0]['id']}"
            self.calls.append((args[0]["id"], priority, args[2:]))
            return fut

    spec = _spec(alphas=[20, 30], freqs=[1, 10])
    pts = points(spec)
    c = Client()
    futs = _submit(c, spec, pts, pts, Path(tmp_path))
    ids = [i for i, _, _ in c.calls]
    assert ids == ["alpha30_freq1_g0.5_F0_seed0", "alpha30_freq10_g0.5_F0_seed0",
                   "alpha20_freq1_g0.5_F0_seed0", "alpha20_freq10_g0.5_F0_seed0"]
    prio = [p for _, p, _ in c.calls]
    assert prio == sorted(prio, reverse=True) and len(set(prio)) == 4
    assert c.calls[0][2] == () and c.calls[1][2][1] == "fut-alpha30_freq1_g0.5_F0_seed0"
    assert c.calls[1][2][0].endswith("points/alpha30_freq1_g0.5_F0_seed0")
    assert len(futs) == 4
    # a finished donor: its group's other point uses its folder, with no future to wait for
    c = Client()
    _submit(c, spec, pts, [p for p in pts if p["id"] != "alpha30_freq1_g0.5_F0_seed0"], Path(tmp_path))
    assert c.calls[0][0] == "alpha30_freq10_g0.5_F0_seed0" and c.calls[0][2][1] is None
