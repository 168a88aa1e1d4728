"""One ownership rule for every command that writes a folder (issue 29): a manifest that names
anything but the command's own bare output names is refused and nothing outside the folder is
touched; each command refuses another command's folder; a kill -9 while a command writes leaves
the folder marked incomplete, and the same command then replaces it cleanly; a sweep never mixes
two protocols; a failed start never blocks the corrected rerun."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rodwarp.cli import app
from rodwarp.rodset.commands import SIMULATE_OUTPUTS, SWEEP_OUTPUTS
from rodwarp.rodset.rundir import MANIFEST

runner = CliRunner()
SHORT = ["simulate", "--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02",
         "--save-every", "0.01", "--checkpoint-every", "0.01", "--device", "cpu", "--quiet"]
PHANTOM = ["phantom", "random", "--shape", "48", "48", "48", "--n-rods", "4", "--aspect", "8", "--radius", "2.5",
           "--cnr", "12"]


def _err(res) -> str:
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:") and "Traceback" not in res.output, res.output
    return lines[0]


def _manifest(d: Path) -> dict:
    return json.loads((d / MANIFEST).read_text())


def _tree(d: Path) -> dict:
    """Every file under ``d`` with its bytes: a folder that must not change."""
    return {str(p.relative_to(d)): p.read_bytes() for p in sorted(d.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def sim_run(tmp_path_factory):
    """A finished simulate run (shared; tests copy it before they change it)."""
    out = tmp_path_factory.mktemp("sim") / "run"
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    assert res.exit_code == 0, res.output
    return out


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    shutil.copytree(src, dst)
    return dst


def _victim(tmp_path: Path) -> Path:
    """A folder outside every run that a hostile manifest points at."""
    v = tmp_path / "precious"
    (v / "sub").mkdir(parents=True)
    (v / "data.txt").write_text("keep me")
    (v / "sub" / "more.bin").write_bytes(b"\x00\x01")
    return v


# ------------------------------------------------------------------ hostile manifests


@pytest.mark.parametrize("entry", ["ABS", "../precious", "../../precious", "vtk/../../precious", "notes.txt", "",
                                   "summary.json/.."])
def test_manifest_naming_paths_outside_or_foreign_names_is_refused_and_nothing_changes(entry, sim_run, tmp_path):
    victim = _victim(tmp_path)
    run = _copy(sim_run, tmp_path / "run")
    (run / "notes.txt").write_text("the user's own file")
    m = _manifest(run)
    m["outputs"] = [*m["outputs"], str(victim) if entry == "ABS" else entry]
    (run / MANIFEST).write_text(json.dumps(m))
    before_victim, before_run = _tree(victim), _tree(run)
    for args in ([*SHORT, "--seed", "1", "--overwrite", "--out", str(run)],    # replace the run
                 ["analyze", str(run), "--out", str(run), "--overwrite", "--quiet", "--no-figures"],
                 [*SHORT, "--resume", "--out", str(run)]):
        res = runner.invoke(app, args)
        line = _err(res)
        assert res.exit_code == 2 and "deletes nothing" in line and MANIFEST in line, line
        assert _tree(victim) == before_victim and _tree(run) == before_run


def test_analysis_folder_with_a_hostile_manifest_is_refused_by_a_plain_analyze(sim_run, tmp_path):
    victim = _victim(tmp_path)
    run = _copy(sim_run, tmp_path / "run")
    res = runner.invoke(app, ["analyze", str(run), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    a = run / "analysis"
    m = _manifest(a)
    m["outputs"].append(str(victim))
    (a / MANIFEST).write_text(json.dumps(m))
    before = _tree(victim)
    res = runner.invoke(app, ["analyze", str(run), "--quiet", "--no-figures"])  # would replace its own analysis
    assert res.exit_code == 2 and "deletes nothing" in _err(res)
    assert _tree(victim) == before and (a / "fields.zarr").exists()


def test_unknown_command_in_a_manifest_is_refused(sim_run, tmp_path):
    run = _copy(sim_run, tmp_path / "run")
    m = _manifest(run)
    m["kind"] = "wipe"
    (run / MANIFEST).write_text(json.dumps(m))
    before = _tree(run)
    res = runner.invoke(app, [*SHORT, "--overwrite", "--out", str(run)])
    assert res.exit_code == 2 and "unknown command 'wipe'" in _err(res)
    assert _tree(run) == before


def test_sweep_and_phase_diagram_refuse_a_hostile_manifest(tmp_path):
    victim = _victim(tmp_path)
    sw = tmp_path / "sw"
    sw.mkdir()
    (sw / MANIFEST).write_text(json.dumps({"format": "rodwarp-run", "kind": "sweep", "complete": True,
                                           "outputs": ["results.csv", str(victim)], "parameters": {}}))
    (sw / "results.csv").write_text("id,alpha\n")
    before = _tree(victim)
    res = runner.invoke(app, ["sweep", "--alpha", "20", "--freq", "1", "--overwrite", "--out", str(sw), "--quiet"])
    assert res.exit_code == 2 and "deletes nothing" in _err(res)
    res = runner.invoke(app, ["phase-diagram", str(sw)])
    assert res.exit_code == 2 and "deletes nothing" in _err(res)
    assert _tree(victim) == before and (sw / "results.csv").exists()


# ------------------------------------------------------------ another command's folder


def test_each_writing_command_refuses_another_commands_folder(sim_run, tmp_path):
    run = _copy(sim_run, tmp_path / "run")
    before = _tree(run)
    tif = tmp_path / "p.tif"
    assert runner.invoke(app, [*PHANTOM, "--out", str(tif)]).exit_code == 0
    cases = [
        (["segment", str(tif), "--voxel-size", "1", "--units", "voxel", "--out", str(run), "--quiet"], "simulate"),
        (["analyze", str(run), "--out", str(run), "--quiet"], "simulate"),
        ([*PHANTOM, "--out", str(run / "stack.tif")], "simulate"),
        (["sweep", "--alpha", "20", "--freq", "1", "--out", str(run), "--quiet"], "simulate"),
        (["phase-diagram", str(run)], "not a sweep"),
    ]
    for args, fragment in cases:
        res = runner.invoke(app, args)
        line = _err(res)
        assert res.exit_code == 2 and fragment in line, (args, line)
        assert _tree(run) == before, args
    # a segmentation folder: simulate and analyze refuse it too
    seg = tmp_path / "seg"
    res = runner.invoke(app, ["segment", str(tif), "--out", str(seg), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    assert _manifest(seg)["kind"] == "segment" and _manifest(seg)["complete"]
    seg_before = _tree(seg)
    for args in ([*SHORT, "--out", str(seg)], ["analyze", str(seg / "rods.npz"), "--out", str(seg), "--quiet"]):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and "holds a finished segment run" in _err(res), args
    assert _tree(seg) == seg_before
    # a TIFF that is not a phantom (a real scan) is not replaced by a phantom
    scan = tmp_path / "scan.tif"
    scan.write_bytes(b"II*\x00 a real scan")
    res = runner.invoke(app, [*PHANTOM, "--out", str(scan)])
    assert res.exit_code == 2 and "not a rodwarp phantom" in _err(res)
    assert scan.read_bytes() == b"II*\x00 a real scan"


# ------------------------------------------------------------------ kill -9 mid-write

_KILLER = """
import os, signal, sys
from pathlib import Path
target, n = sys.argv[1], int(sys.argv[2])
seen = [0]
real = os.replace
def replace(src, dst, *a, **k):
    # an atomic write lands by this rename: die (kill -9) instead of the n-th landing of `target`
    if Path(dst).name == target:
        seen[0] += 1
        if seen[0] == n:
            os.kill(os.getpid(), signal.SIGKILL)
    return real(src, dst, *a, **k)
os.replace = replace
from rodwarp.cli import main
sys.exit(main(sys.argv[3:]))
"""


def _killed(target: str, args: list[str], cwd: Path, n: int = 1) -> None:
    r = subprocess.run([sys.executable, "-c", _KILLER, target, str(n), *args], cwd=cwd, capture_output=True,
                       text=True, timeout=600)
    assert r.returncode == -9, (r.returncode, r.stderr[-2000:])


def test_kill_while_simulate_writes_marks_the_folder_and_overwrite_replaces_it(tmp_path):
    out = tmp_path / "run"
    _killed("final.npz", [*SHORT, "--out", str(out)], tmp_path)
    m = _manifest(out)
    assert m["complete"] is False and m["status"] == "running" and not (out / "final.npz").exists()
    res = runner.invoke(app, [*SHORT, "--out", str(out)])  # not silently replaced: it holds resumable work
    assert res.exit_code == 2 and "holds an unfinished simulate run" in _err(res)
    res = runner.invoke(app, [*SHORT, "--seed", "1", "--overwrite", "--out", str(out)])
    assert res.exit_code == 0, res.output
    m2 = _manifest(out)
    assert m2["complete"] and m2["run_id"] != m["run_id"]
    assert json.loads((out / "summary.json").read_text())["seed"] == 1


def test_kill_while_analyze_writes_then_the_same_analyze_replaces_it(sim_run, tmp_path):
    run = _copy(sim_run, tmp_path / "run")
    _killed("summary.json", ["analyze", str(run), "--quiet", "--no-figures"], tmp_path)
    a = run / "analysis"
    assert _manifest(a)["complete"] is False and not (a / "summary.json").exists()
    res = runner.invoke(app, ["analyze", str(run), "--quiet", "--no-figures", "--radius", "0.2"])
    assert res.exit_code == 0, res.output
    m = _manifest(a)
    assert m["complete"] and m["parameters"]["radius"] == pytest.approx(0.2)
    assert json.loads((a / "summary.json").read_text())["radius"] == pytest.approx(0.2)


def test_kill_while_segment_replaces_an_earlier_segmentation(tmp_path):
    a, b = tmp_path / "a.tif", tmp_path / "b.tif"
    assert runner.invoke(app, [*PHANTOM, "--seed", "1", "--out", str(a)]).exit_code == 0
    assert runner.invoke(app, [*PHANTOM, "--n-rods", "6", "--seed", "2", "--out", str(b)]).exit_code == 0
    seg = tmp_path / "seg"
    res = runner.invoke(app, ["segment", str(a), "--out", str(seg), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    # killed while writing b's outputs over a's: b's rods may already be there, a's summary not
    _killed("summary.json", ["segment", str(b), "--out", str(seg), "--quiet", "--no-figures"], tmp_path)
    m = _manifest(seg)
    assert m["complete"] is False and m["parameters"]["input"] == str(b.resolve())
    assert not (seg / "summary.json").exists()  # a's summary is gone, not passing for b's
    res = runner.invoke(app, ["segment", str(b), "--out", str(seg), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    s = json.loads((seg / "summary.json").read_text())
    assert _manifest(seg)["complete"] and s["input"] == str(b) and s["n_rods"] == 6


def test_kill_while_phantom_writes_marks_its_truth_incomplete_and_a_rerun_replaces_it(tmp_path):
    tif = tmp_path / "p.tif"
    assert runner.invoke(app, [*PHANTOM, "--seed", "1", "--out", str(tif)]).exit_code == 0
    js = tmp_path / "p_truth.json"
    assert json.loads(js.read_text())["complete"] is True
    _killed("p_truth.npz", [*PHANTOM, "--n-rods", "6", "--seed", "2", "--out", str(tif)], tmp_path)
    assert json.loads(js.read_text())["complete"] is False  # the new TIFF is in, its rods are not
    res = runner.invoke(app, [*PHANTOM, "--n-rods", "6", "--seed", "2", "--out", str(tif)])
    assert res.exit_code == 0, res.output
    meta = json.loads(js.read_text())
    assert meta["complete"] is True and meta["n_rods"] == 6 and meta["seed"] == 2


def test_kill_while_sweep_or_its_phase_diagram_writes_then_the_same_command_completes(tmp_path):
    sw = tmp_path / "sw"
    args = ["sweep", "--alpha", "20", "--freq", "1", "--entangle-duration", "0.02", "--duration", "0.02",
            "--save-every", "0.01", "--workers", "1", "--device", "cpu", "--quiet", "--no-figures",
            "--set", "n_rods=12", "--out", str(sw)]
    _killed("sweep.json", args, tmp_path)
    assert _manifest(sw)["complete"] is False and _manifest(sw)["kind"] == "sweep"
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    m = _manifest(sw)
    assert m["complete"] and m["n_points"] == 1
    rows = (sw / "results.csv").read_text().splitlines()
    assert len(rows) == 2 and ",ok," in rows[1] + ","
    # phase-diagram writes into the sweep's folder: killed mid-way, the manifest says so; rerun, it is whole
    _killed("alpha_star.csv", ["phase-diagram", str(sw)], tmp_path)
    assert _manifest(sw)["parts"]["phase_diagram"]["complete"] is False
    res = runner.invoke(app, ["phase-diagram", str(sw)])
    assert res.exit_code == 0, res.output
    assert _manifest(sw)["parts"]["phase_diagram"]["complete"] is True and (sw / "alpha_star.csv").exists()


# ---------------------------------------------------------------- sweeps of two protocols


def test_a_sweep_of_another_protocol_is_refused_naming_what_differs(tmp_path):
    from rodwarp.rodset import rundir
    from rodwarp.experiments._sweep import SweepSpec, protocol

    sw = tmp_path / "sw"
    first = SweepSpec(alphas=[20.0], freqs=[1.0], duration=0.02, entangle_duration=0.02,
                      overrides={"save_every": 0.01})
    rundir.claim(sw, "sweep", protocol(first), SWEEP_OUTPUTS, append=True).complete()
    (sw / "results.csv").write_text("id\nx\n")
    # more points of the same protocol: allowed (another grid, device, share-entangling)
    same = SweepSpec(alphas=[40.0, 20.0], freqs=[1.0, 10.0], duration=0.02, entangle_duration=0.02, device="cpu",
                     share_entangling=False, overrides={"save_every": 0.01})
    rundir.check(sw, "sweep", protocol(same), SWEEP_OUTPUTS, append=True)
    res = runner.invoke(app, ["sweep", "--alpha", "20", "--freq", "1", "--duration", "0.05", "--entangle-duration",
                              "0.02", "--save-every", "0.01", "--out", str(sw), "--quiet"])
    line = _err(res)
    assert res.exit_code == 2 and "another protocol" in line and "duration 0.02 there, 0.05 here" in line
    assert (sw / "results.csv").read_text() == "id\nx\n"
    res = runner.invoke(app, ["sweep", "--alpha", "20", "--freq", "1", "--duration", "0.02", "--entangle-duration",
                              "0.02", "--save-every", "0.01", "--set", "mu=0.3", "--out", str(sw), "--quiet"])
    assert res.exit_code == 2 and "overrides" in _err(res)


def test_a_legacy_sweep_folder_is_compared_through_its_sweep_json(tmp_path):
    from rodwarp.experiments._sweep import SweepSpec
    from rodwarp.rodset import rundir
    from rodwarp.experiments._sweep import _legacy_protocol, protocol

    sw = tmp_path / "sw"
    sw.mkdir()
    spec = SweepSpec(alphas=[20.0], freqs=[1.0], duration=0.02, entangle_duration=0.02)
    (sw / "sweep.json").write_text(json.dumps({"spec": spec.to_dict()}))
    (sw / "results.csv").write_text("id\n")
    assert _legacy_protocol(sw) == protocol(spec)
    other = SweepSpec(alphas=[20.0], freqs=[1.0], duration=0.5, entangle_duration=0.02)
    with pytest.raises(Exception, match="another protocol"):
        rundir.check(sw, "sweep", protocol(other), SWEEP_OUTPUTS, append=True, legacy=_legacy_protocol(sw))


# ---------------------------------------------------------------- failed starts


def test_failed_starts_do_not_block_the_corrected_rerun(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, [*SHORT, "--alpha", "3", "--out", str(out)])  # 12 fat rods do not fit the box
    assert res.exit_code == 2 and "placed only" in _err(res)
    m = _manifest(out)
    assert m["status"] == "failed" and "placed only" in m["error"]  # the record says why
    res = runner.invoke(app, [*SHORT, "--out", str(out)])  # the corrected command, no --overwrite
    assert res.exit_code == 0, res.output
    assert _manifest(out)["complete"]
    # --resume in a folder that never held a run: refused, nothing left behind, and the advice works
    fresh = tmp_path / "fresh"
    res = runner.invoke(app, [*SHORT, "--resume", "--out", str(fresh)])
    line = _err(res)
    assert res.exit_code == 2 and "nothing to resume" in line and "without --resume" in line
    assert not (fresh / MANIFEST).exists()
    assert runner.invoke(app, [*SHORT, "--out", str(fresh)]).exit_code == 0


def test_failed_run_with_outputs_names_the_whole_cause_and_no_resume_without_checkpoints(tmp_path):
    from rodwarp.rodset import rundir

    out = tmp_path / "run"
    cause = "the disk filled while writing trajectory.zarr at t = 0.35 s; " + "x" * 30 + " free some space please"
    rundir.claim(out, "simulate", {"seed": 0}, SIMULATE_OUTPUTS)
    (out / "metrics.csv").write_text("time\n0\n")
    rundir.mark_failed(out, OSError(cause))
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    line = _err(res)
    assert res.exit_code == 2 and "holds a failed simulate run" in line and "--overwrite" in line
    assert "--resume" not in line  # there is no checkpoint: --resume would send the user back
    assert "free some space please" in line or line.count(" ...") == 1  # cut at a word, never mid-word
    res = runner.invoke(app, [*SHORT, "--resume", "--out", str(out)])
    assert res.exit_code == 2 and "--overwrite instead of --resume" in _err(res)
    assert runner.invoke(app, [*SHORT, "--overwrite", "--out", str(out)]).exit_code == 0


def test_cause_is_cut_at_a_word_boundary():
    from rodwarp.rodset.rundir import _cause

    text = "placed only 5 of 16 rods after 420000 attempts; lower --n-rods or enlarge --box " * 4
    short = _cause(text, 80)
    assert short.endswith(" ...") and len(short) <= 84
    assert text.startswith(short[:-4]) and text[len(short) - 4] == " "  # the cut falls between words


def test_a_folder_being_written_by_a_live_run_is_refused_even_with_overwrite(tmp_path):
    import socket

    out = tmp_path / "run"
    out.mkdir()
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (out / MANIFEST).write_text(json.dumps({"format": "rodwarp-run", "kind": "simulate", "complete": False,
                                                "status": "running", "host": socket.gethostname(),
                                                "pid": sleeper.pid, "outputs": ["summary.json"]}))
        res = runner.invoke(app, [*SHORT, "--overwrite", "--out", str(out)])
        assert res.exit_code == 2 and "being written by a running simulate run" in _err(res)
    finally:
        sleeper.kill()
        sleeper.wait()
    assert runner.invoke(app, [*SHORT, "--overwrite", "--out", str(out)]).exit_code == 0
    assert os.path.exists(out / "final.npz")
