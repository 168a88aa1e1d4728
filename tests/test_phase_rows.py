"""`rodwarp phase-diagram` on a results.csv that no sweep wrote (issue 29, classes 4 and 6).

Every refusal is one line on stderr, exit 2, no traceback, naming the row's point id and the
column (or the file and the missing columns), and nothing is drawn. The rows are written by
the sweep's own writer (:func:`rodwarp.experiments.write_results`), so the header is the real
one, and then spoiled the way a hand edit, a concatenation or a disk error would.
"""

from __future__ import annotations

import csv
import math

import pytest

from rodwarp.cli import main
from rodwarp.experiments import write_results
from rodwarp.experiments._sweep import read_results

#: the point whose row each case spoils
ID = "alpha100_freq10_g0.5_F0_seed1"


def _row(alpha, freq, seed, stable, f):
    """A row as :func:`rodwarp.experiments.run_point` returns it (the parameters, then the results)."""
    pid = f"alpha{alpha:g}_freq{freq:g}_g0.5_F0_seed{seed}"
    amp = 0.001
    return {"id": pid, "alpha": float(alpha), "freq": float(freq), "gravity": 0.5, "static_load": 0.0, "seed": seed,
            "amplitude": amp, "entangle_duration": 0.02, "duration": 0.02, "n_rods": 12, "save_every": 0.01,
            "a_over_g": 4 * math.pi**2 * freq**2 * amp / 0.5, "F_tilde": 0.0,
            "largest_cluster_fraction": f, "height_kept": 0.9 if stable else 0.3,
            "persistence": 1.0 if stable else 0.1, "rods_left": 0.0, "contacts_per_rod": 3.0, "cv_e": 1.2,
            "mean_e": 2.0, "std_e": 2.4, "stable": stable, "max_penetration_over_d": 0.01, "device": "cpu",
            "wall_s": 1.5, "entangled_from": "", "worker": "host:1", "status": "ok"}


def _sweep(d, spoil=None):
    """A sweep folder's results.csv: alphas 50, 100, 200 at one a/g, two seeds; alpha 100 is
    stable for seed 1 only. ``spoil(rows)`` edits the row dicts before they are written."""
    rows = [_row(a, 10, s, a > 100 or (a == 100 and s == 1), 0.3 if a < 100 else 0.8)
            for a in (200, 100, 50) for s in (0, 1)]
    if spoil:
        spoil(rows)
    write_results(d / "results.csv", rows)
    return d


def _set(pid, col, value):
    def spoil(rows):
        next(r for r in rows if r["id"] == pid)[col] = value
    return spoil


def _cli(capsys, d):
    rc = main(["phase-diagram", str(d)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def _refused(capsys, d, *words):
    rc, out, err = _cli(capsys, d)
    assert rc == 2, (out, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err
    assert "Traceback" not in out + err and "internal error" not in err
    for w in words:
        assert w in lines[0], (w, lines[0])
    assert not (d / "alpha_star.csv").exists() and not list(d.glob("phase_*.png"))  # nothing drawn
    return lines[0]


def test_a_sweeps_own_file_is_drawn_and_failed_rows_are_counted(tmp_path, capsys):
    # the baseline of the cases below: the real writer's file passes; a failed point's row
    # (status not ok, empty results) is left out, and the output says how many were
    def spoil(rows):
        bad = dict(rows[-1], id="alpha3_freq10_g0.5_F0_seed0", alpha=3.0, status="error: placed only 5 of 12 rods")
        for k in ("largest_cluster_fraction", "height_kept", "persistence", "stable", "cv_e"):
            bad[k] = None
        rows.append(bad)
    _sweep(tmp_path, spoil)
    rc, out, err = _cli(capsys, tmp_path)
    assert rc == 0, err
    notes = [ln for ln in err.splitlines() if ln.startswith("note:") and "failed row" in ln]  # notes: stderr
    assert len(notes) == 1 and "1 failed row(s) skipped" in notes[0] and "alpha3_freq10" in notes[0]
    assert out.strip().endswith(f"-> {tmp_path}") and len(out.strip().splitlines()) == 1  # the result line
    table = list(csv.DictReader(open(tmp_path / "alpha_star.csv")))
    assert float(table[0]["alpha_star"]) == pytest.approx(100.0)


def test_two_rows_of_one_point_with_opposite_verdicts_are_refused(tmp_path, capsys):
    # the row appended again with the other verdict: both would count as seeds of alpha 100
    def spoil(rows):
        r = next(r for r in rows if r["id"] == ID)
        rows.append(dict(r, stable=not r["stable"]))
    line = _refused(capsys, _sweep(tmp_path, spoil), ID, "stable", "unstable", "duplicate")
    assert "2 rows" in line


@pytest.mark.parametrize("col, value, words", [
    ("alpha", float("nan"), ("alpha", "empty")),           # the writer writes NaN as an empty cell
    ("alpha", "nan", ("alpha", "'nan'", "not a finite number")),
    ("a_over_g", "inf", ("a_over_g", "'inf'", "not a finite number")),
    ("a_over_g", "-inf", ("a_over_g", "not a finite number")),
    ("largest_cluster_fraction", "abc", ("largest_cluster_fraction", "not a number")),
    ("largest_cluster_fraction", 1.5, ("largest_cluster_fraction", "out of range")),
    ("alpha", 0.5, ("alpha", "out of range")),
    ("gravity", 0.0, ("gravity", "out of range")),
    ("cv_e", "1e999", ("cv_e", "not a finite number")),
    ("stable", "maybe", ("stable", "'maybe'", "not True or False")),
    ("stable", None, ("stable", "not True or False")),
])
def test_an_ok_row_with_a_bad_value_is_refused_by_id_and_column(tmp_path, capsys, col, value, words):
    _refused(capsys, _sweep(tmp_path, _set(ID, col, value)), ID, *words)


def test_an_ok_row_whose_id_is_not_a_folder_name_is_refused(tmp_path, capsys):
    # the id names the folder phase-diagram reads the point's metrics from: never a path out
    _refused(capsys, _sweep(tmp_path, _set(ID, "id", "../../etc")), "'../../etc'", "folder name")


def test_a_binary_results_csv_is_refused(tmp_path, capsys):
    (tmp_path / "results.csv").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4)
    _refused(capsys, tmp_path, "results.csv is not a text CSV (not UTF-8")


def test_a_results_csv_with_nul_bytes_is_refused(tmp_path, capsys):
    _sweep(tmp_path)
    p = tmp_path / "results.csv"
    p.write_bytes(p.read_bytes().replace(b"\n", b"\x00\n", 2))
    _refused(capsys, tmp_path, "results.csv is not a text CSV (it holds NUL bytes)")


def test_a_csv_without_the_needed_columns_is_refused_by_name(tmp_path, capsys):
    (tmp_path / "results.csv").write_text("name,value\nfoo,1\n")
    _refused(capsys, tmp_path, "lacks the column(s) id, alpha, gravity, largest_cluster_fraction, stable, status",
             "'name'")


def test_a_row_longer_than_the_header_is_refused(tmp_path, capsys):
    _sweep(tmp_path)
    p = tmp_path / "results.csv"
    lines = p.read_text().splitlines()
    lines[2] += ",extra,cells"
    p.write_text("\n".join(lines) + "\n")
    _refused(capsys, tmp_path, "data row 2", "2 more cell(s)")


def test_a_results_csv_that_is_a_folder_is_refused(tmp_path, capsys):
    (tmp_path / "results.csv").mkdir()
    _refused(capsys, tmp_path, "results.csv is a folder")


def test_a_binary_metrics_csv_of_a_point_is_refused_by_file(tmp_path, capsys):
    _sweep(tmp_path)
    (tmp_path / "points" / ID).mkdir(parents=True)
    (tmp_path / "points" / ID / "metrics.csv").write_bytes(b"\xff\xfe" + bytes(range(256)))
    rc, out, err = _cli(capsys, tmp_path)
    # found while drawing: a note that the drawing runs long may come first (on a slow host)
    lines = [ln for ln in err.strip().splitlines() if not ln.startswith("note: drawing the phase diagram")]
    assert rc == 2 and len(lines) == 1 and lines[0].startswith("error: ") and "Traceback" not in err
    assert f"points/{ID}/metrics.csv is not a text CSV (not UTF-8: it holds byte 0x" in err


def test_read_results_refuses_garbage_for_the_sweep_too(tmp_path):
    # run_sweep reads the folder's results.csv to skip finished points: garbage is refused
    # there too (one line) instead of an internal error or rows keyed by None
    from rodwarp.errors import RodwarpError

    p = tmp_path / "results.csv"
    p.write_bytes(b"\x00\xff\xfe\x80binary")
    with pytest.raises(RodwarpError, match="not a text CSV"):
        read_results(p)
    p.write_text("alpha,freq\n1,2\n")
    with pytest.raises(RodwarpError, match=r"lacks the column\(s\) id, status"):
        read_results(p)
    p.write_text("")
    assert read_results(p) == []
    assert read_results(tmp_path / "none.csv") == []
