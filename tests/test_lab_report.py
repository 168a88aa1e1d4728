"""scripts/lab_experiments.py: its report reads a run still going as the finished run reports
itself, and compares runs over the span the slowest has reached."""

import json
import shutil
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "scripts"))

import lab_experiments  # noqa: E402

from rodwarp.experiments import ProtocolParams, run_protocol  # noqa: E402


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A finished tiny shaking run, and a copy of it that looks still going (no summary.json,
    its metadata says running)."""
    root = tmp_path_factory.mktemp("lab_runs")
    p = ProtocolParams(protocol="lab", alpha=20, length=0.05, gravity=9.81, freq=5.0, amplitude=0.025,
                       save_every=0.025, fields_every=0.0, checkpoint_every=0.5, device="cpu", n_rods=20,
                       pour_duration=0.3, lift_duration=0.1, duration=0.6)
    run_protocol(p, root / "shake_alpha20_seed0", progress=False)
    going = root / "shake-rigid_alpha20_seed0"
    shutil.copytree(root / "shake_alpha20_seed0", going)
    (going / "summary.json").unlink()
    meta = json.loads((going / "rodwarp-run.json").read_text())
    (going / "rodwarp-run.json").write_text(json.dumps({**meta, "complete": False, "status": "running"}))
    return root


def test_a_run_in_progress_reads_as_its_own_summary(runs):
    done = json.loads((runs / "shake_alpha20_seed0" / "summary.json").read_text())
    going = lab_experiments._in_progress(runs / "shake-rigid_alpha20_seed0")
    assert going["incomplete"]["shaken_s"] == pytest.approx(0.6)
    for k in ("persistence", "largest_cluster_fraction"):
        assert going["lab"]["shake"]["cohesion"][k] == pytest.approx(done["lab"]["shake"]["cohesion"][k])
    assert going["lab"]["shake"]["landed"]["centroid_height_ratio"] == pytest.approx(
        done["lab"]["shake"]["landed"]["centroid_height_ratio"])
    assert going["lab"]["lift"]["height_kept_after_lift"] == pytest.approx(
        done["lab"]["lift"]["height_kept_after_lift"])
    assert going["n_rods"] == done["n_rods"] == 20


def test_the_report_compares_runs_over_the_span_the_slowest_reached(runs, tmp_path):
    assert lab_experiments.main(["report", "--runs", str(runs), "--out", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "lab_experiments.json").read_text())
    assert [r["run"] for r in rec["runs"]["shake"]] == ["shake_alpha20_seed0"]
    assert rec["runs"]["shake_rigid"][0]["incomplete"]["status"] == "running"
    span = rec["same_span"]
    assert span["span_s"] == pytest.approx(0.6)
    assert {r["run"] for r in span["runs"]} == {"shake_alpha20_seed0", "shake-rigid_alpha20_seed0"}
    a, b = span["runs"]
    assert a["tau_f"] == pytest.approx(b["tau_f"]) and a["f"] == pytest.approx(b["f"])
    # one alpha gives no transition; the command names no folder of this machine
    assert rec["transition"] == {"sag_rule": {}, "rigid": {}}
    assert str(runs) not in rec["command"] and str(tmp_path) not in rec["command"]
    md = (tmp_path / "lab_experiments.md").read_text()
    assert "in progress: 0.6 of 0.6 s shaken" in md
    assert (tmp_path / "lab_shake.png").stat().st_size > 0
