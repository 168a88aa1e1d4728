"""The conventions every command shares (docs/commands.md, "What every command shares").

The result line on stdout and progress and notes on stderr; flags shown as flags in
``--help``; ``--quiet``, ``--out`` and ``--overwrite`` alike on every writing command;
``--device auto`` wherever Warp runs; a note once a long phase has run
:data:`rodwarp._util.NOTE_AFTER_S` (tested with the threshold at 0, not by waiting). That the
README's commands run as printed after its quick start is ``tests/test_readme.py``.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from rodwarp import _util
from rodwarp.cli import app, main

runner = CliRunner()
#: rich's help table unwrapped, so an option and its help stay on one line
WIDE = {"COLUMNS": "200"}
TINY = ["simulate", "--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02",
        "--save-every", "0.01", "--device", "cpu"]
PHANTOM = ["phantom", "random", "--shape", "48", "48", "48", "--n-rods", "4", "--aspect", "8", "--radius", "2.5"]
#: the commands that write (each takes --quiet, --out and --overwrite)
WRITING = ("simulate", "analyze", "phantom", "segment", "sweep", "phase-diagram")


def _lines(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.strip()]


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 12-rod simulate run without --quiet, every phase noted at once (threshold 0 s)."""
    out = tmp_path_factory.mktemp("conv") / "run"
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(_util, "NOTE_AFTER_S", 0.0)
        res = runner.invoke(app, [*TINY, "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out, res


# ------------------------------------------------------------------ stdout: the result alone


def test_simulate_prints_its_result_on_stdout_and_its_progress_on_stderr(tiny_run):
    out, res = tiny_run
    lines = _lines(res.stdout)
    assert len(lines) == 1 and lines[0].startswith("alpha=20 n_rods=12") and lines[0].endswith(f"-> {out}")
    assert "━" not in res.stdout
    assert "entangle" in res.stderr and "stability" in res.stderr and "t=0.02/0.02 s" in res.stderr


def test_the_placement_of_the_rods_says_so_once_it_runs_long(tiny_run):
    _, res = tiny_run
    assert res.stderr.count("note: placing 12 rods...") == 1, res.stderr
    assert "12/12 rods" in res.stderr  # the bar over the rods placed


def test_analyze_prints_its_result_on_stdout_and_its_progress_on_stderr(tiny_run):
    run, _ = tiny_run
    res = runner.invoke(app, ["analyze", str(run), "--no-figures", "--device", "cpu"])
    assert res.exit_code == 0, res.output
    lines = _lines(res.stdout)
    assert len(lines) == 1 and lines[0].startswith("mean phi=") and lines[0].endswith(f"-> {run / 'analysis'}")
    assert "━" not in res.stdout and "fields" in res.stderr and "voxels" in res.stderr


# ------------------------------------------------------------------------- --quiet and notes


def test_phantom_quiet_prints_nothing_on_stderr(tmp_path, monkeypatch):
    monkeypatch.setattr(_util, "NOTE_AFTER_S", 0.0)  # the rendering's note, were it not quiet
    res = runner.invoke(app, [*PHANTOM, "--out", str(tmp_path / "a.tif")])
    assert res.exit_code == 0, res.output
    assert "note: rendering the 48 x 48 x 48 voxel phantom..." in res.stderr
    res = runner.invoke(app, [*PHANTOM, "--out", str(tmp_path / "b.tif"), "--quiet"])
    assert res.exit_code == 0, res.output
    assert res.stderr == ""
    lines = _lines(res.stdout)
    assert len(lines) == 1 and lines[0].endswith(f"-> {tmp_path / 'b.tif'}")


def test_quiet_reaches_the_notes_the_options_do_not(tmp_path, monkeypatch, capsys):
    # the packing is called below the command's options: a command's --quiet reaches it through
    # set_quiet (read while the options are parsed, so a refused command sets it too)
    from rodwarp.experiments import random_packing

    def placement_err(**kw) -> str:
        random_packing(12, 1.0, 0.05, (2.0, 2.0, 2.0), device="cpu", **kw)
        return capsys.readouterr().err

    monkeypatch.setattr(_util, "NOTE_AFTER_S", 0.0)
    was = _util.quiet()
    try:
        assert main([*PHANTOM, "--out", str(tmp_path / "p.tif"), "--cnr", "nan"]) == 2
        capsys.readouterr()
        assert not _util.quiet() and "note: placing 12 rods..." in placement_err()
        assert main([*PHANTOM, "--out", str(tmp_path / "p.tif"), "--cnr", "nan", "--quiet"]) == 2
        capsys.readouterr()
        assert _util.quiet() and placement_err() == ""
        assert placement_err(progress=True).count("note: placing 12 rods...") == 1
        _util.set_quiet(False)
        assert placement_err(progress=False) == ""
    finally:
        _util.set_quiet(was)


def test_a_library_call_is_quiet_by_default():
    import subprocess

    code = "from rodwarp import _util; print(_util.quiet())"
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert r.stdout.strip() == "True"


def test_a_slow_phase_is_silent_while_short_and_says_so_once_long(capsys):
    with _util.slow_phase("quick", 3, after=5.0, enabled=True) as update:
        for k in range(4):
            update(k)
    assert capsys.readouterr().err == ""
    # no update at all (a phase without a progress hook): the timer speaks for it
    with _util.slow_phase("waiting", after=0.05, enabled=True):
        time.sleep(1.0)
    err = capsys.readouterr().err
    assert err.count("note: waiting...") == 1, err
    with _util.slow_phase("long", 2, after=0.0, unit="items", enabled=True) as update:
        update(1)
        update(2)
    err = capsys.readouterr().err
    assert err.count("note: long...") == 1 and "2/2 items" in err, err
    with _util.slow_phase("silenced", 2, after=0.0, enabled=False) as update:
        update(2)
    assert capsys.readouterr().err == ""


# ----------------------------------------------------------------------------------- --help


def _commands() -> list[str]:
    return sorted(typer.main.get_command(app).commands)


def _help(command: str) -> str:
    res = runner.invoke(app, [command, "--help"], env=WIDE)
    assert res.exit_code == 0, res.output
    return res.stdout


def test_help_shows_flags_as_flags_on_every_command():
    assert set(WRITING) | {"version"} == set(_commands())
    for command in _commands():
        text = _help(command)
        assert "<bool>" not in text, (command, [ln for ln in text.splitlines() if "<bool>" in ln])
    assert "<bool>" not in runner.invoke(app, ["--help"], env=WIDE).stdout


def _options(text: str) -> set[str]:
    """The option names a rich ``--help`` table lists (both forms of a ``--x/--no-x`` flag)."""
    names = set()
    for ln in text.splitlines():
        words = [w for w in ln.strip("│ ").split() if w != "*"]
        names |= {w for w in words[:2] if w.startswith("--")}
    return names


@pytest.mark.parametrize("command", WRITING)
def test_every_writing_command_takes_quiet_out_and_overwrite(command):
    assert {"--quiet", "--out", "--overwrite"} <= _options(_help(command))


@pytest.mark.parametrize("command", WRITING)
def test_a_flag_off_by_default_has_no_negative_form(command):
    negatives = {"--no-quiet", "--no-overwrite", "--no-resume", "--no-keep-outside", "--no-entangle", "--no-dark"}
    assert not negatives & _options(_help(command))


def test_a_flag_on_by_default_keeps_its_negative_form():
    assert "--no-figures" in _options(_help("analyze")) and "--no-figures" in _options(_help("segment"))
    assert "--no-rolling" in _options(_help("simulate"))  # no default (the contact law's): both forms


def test_device_is_auto_wherever_warp_runs():
    from rodwarp.analysis import AnalyzeOptions

    assert AnalyzeOptions().device == "auto"
    for command in ("simulate", "analyze", "sweep"):
        line = next(ln for ln in _help(command).splitlines() if "--device " in ln)
        assert "[default: auto]" in line, (command, line)


# ------------------------------------------------------------------------ phase-diagram --out


def _row(alpha: float, seed: int, stable: bool) -> dict:
    """One ok row of results.csv, as run_point returns it."""
    freq, amp, g = 10.0, 0.001, 0.5
    return {"id": f"alpha{alpha:g}_freq{freq:g}_g{g:g}_F0_seed{seed}", "alpha": alpha, "freq": freq, "gravity": g,
            "static_load": 0.0, "seed": seed, "amplitude": amp, "entangle_duration": 0.02, "duration": 0.02,
            "n_rods": 12, "save_every": 0.01, "a_over_g": 4 * math.pi**2 * freq**2 * amp / g, "F_tilde": 0.0,
            "largest_cluster_fraction": 0.8 if stable else 0.3, "height_kept": 0.9 if stable else 0.3,
            "persistence": 1.0 if stable else 0.1, "rods_left": 0.0, "contacts_per_rod": 3.0, "cv_e": 1.2,
            "mean_e": 2.0, "std_e": 2.4, "stable": stable, "max_penetration_over_d": 0.01, "device": "cpu",
            "wall_s": 1.5, "entangled_from": "", "worker": "host:1", "status": "ok"}


def _sweep(d: Path, failed: bool = False) -> Path:
    """A sweep folder's results.csv (alpha 50, 100, 200; two seeds), a failed point's row too."""
    from rodwarp.experiments import write_results

    d.mkdir(parents=True, exist_ok=True)
    rows = [_row(a, s, a > 100) for a in (50.0, 100.0, 200.0) for s in (0, 1)]
    if failed:
        rows.append(dict(_row(3.0, 0, False), status="error: placed only 5 of 12 rods", stable=None,
                         largest_cluster_fraction=None))
    write_results(d / "results.csv", rows)
    return d


def _manifest(d: Path) -> dict:
    return json.loads((d / "rodwarp-run.json").read_text())


def test_phase_diagram_out_writes_there_and_leaves_the_sweep_folder_alone(tmp_path):
    sw, out = _sweep(tmp_path / "sw"), tmp_path / "pd"
    res = runner.invoke(app, ["phase-diagram", str(sw), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert (out / "alpha_star.csv").exists() and (out / "phase_cv_e.png").exists()
    assert not (sw / "alpha_star.csv").exists() and not list(sw.glob("phase_*.png"))
    m = _manifest(out)
    assert m["kind"] == "phase-diagram" and m["complete"] and m["parameters"]["sweep"] == str(sw.resolve())
    lines = _lines(res.stdout)
    assert len(lines) == 1 and lines[0].endswith(f"-> {out}") and "alpha_star.csv" in lines[0]
    # the same sweep's diagram again: replaced without --overwrite
    assert runner.invoke(app, ["phase-diagram", str(sw), "--out", str(out)]).exit_code == 0
    # the default is the sweep's folder, as before
    res = runner.invoke(app, ["phase-diagram", str(sw), "--quiet"])
    assert res.exit_code == 0 and (sw / "alpha_star.csv").exists() and _lines(res.stdout)[0].endswith(f"-> {sw}")


def test_phase_diagram_out_refuses_another_runs_folder_without_overwrite(tmp_path):
    from rodwarp.rodset.commands import ANALYZE_OUTPUTS
    from rodwarp.rodset import rundir

    sw, other, out = _sweep(tmp_path / "sw"), _sweep(tmp_path / "other"), tmp_path / "pd"
    assert runner.invoke(app, ["phase-diagram", str(sw), "--out", str(out)]).exit_code == 0
    before = (out / "alpha_star.csv").read_bytes()
    res = runner.invoke(app, ["phase-diagram", str(other), "--out", str(out)])  # another sweep's diagram
    assert res.exit_code == 2 and "pass --overwrite" in res.stderr and res.stdout == "", res.output
    assert (out / "alpha_star.csv").read_bytes() == before
    res = runner.invoke(app, ["phase-diagram", str(other), "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    assert _manifest(out)["parameters"]["sweep"] == str(other.resolve())
    an = tmp_path / "an"  # another command's run folder
    rundir.claim(an, "analyze", {}, ANALYZE_OUTPUTS).complete()
    (an / "summary.json").write_text("{}")
    res = runner.invoke(app, ["phase-diagram", str(sw), "--out", str(an)])
    assert res.exit_code == 2 and "analyze run" in res.stderr and "pass --overwrite" in res.stderr
    assert not (an / "alpha_star.csv").exists() and (an / "summary.json").exists()


def test_phase_diagram_notes_on_stderr_and_quiet_silences_them(tmp_path, monkeypatch):
    monkeypatch.setattr(_util, "NOTE_AFTER_S", 0.0)
    sw = _sweep(tmp_path / "sw", failed=True)
    res = runner.invoke(app, ["phase-diagram", str(sw)])
    assert res.exit_code == 0, res.output
    assert "1 failed row(s) skipped" in res.stderr and "note: drawing the phase diagram" in res.stderr
    assert len(_lines(res.stdout)) == 1 and "note:" not in res.stdout
    res = runner.invoke(app, ["phase-diagram", str(sw), "--out", str(tmp_path / "pd"), "--quiet"])
    assert res.exit_code == 0 and res.stderr == "", res.output
