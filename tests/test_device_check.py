"""scripts/device_check.sh: one line and nothing written without a GPU; its pure helpers (the
time budget, the sizes that shrink, the agreement comparison, the JUnit counts)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
import device_check as dc  # noqa: E402

NO_GPU_LINE = "device_check: no CUDA device (warp sees only cpu); nothing measured"


def _cuda_available() -> bool:
    from rodwarp import _warp

    _warp.init()
    import warp as wp

    return wp.is_cuda_available()


def _state(path: Path):
    return (path.stat().st_mtime_ns, path.stat().st_size) if path.exists() else None


@pytest.mark.parametrize("out", [False, True], ids=["default-out", "given-out"])
def test_without_a_gpu_one_line_exit_0_and_nothing_written(tmp_path, out):
    if _cuda_available():
        pytest.skip("a CUDA device is present: the script would run the whole check (minutes)")
    given = tmp_path / "results" / "device_check.json"
    defaults = [dc.DEFAULT_OUT, dc.DEFAULT_OUT.with_suffix(".md")]
    before = [_state(p) for p in defaults]
    args = ["--out", str(given)] if out else []
    env = {k: v for k, v in os.environ.items() if k != "PYTHON"}
    env["PYTHON"] = sys.executable
    r = subprocess.run(["bash", str(ROOT / "scripts" / "device_check.sh"), *args], cwd=tmp_path, env=env,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout == NO_GPU_LINE + "\n"
    assert r.stderr == ""
    assert [_state(p) for p in defaults] == before
    assert not (tmp_path / "results").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_step_allowance_is_the_share_plus_what_earlier_steps_left():
    # budget 480 s less the 15 s margin = 465 s; shares 0.5 / 0.25 / 0.25
    assert dc.step_allowance(480, 0.0, "cuda_tests") == pytest.approx(465 * 0.5)
    # the tests took 100 s of their 232.5: the agreement gets 465 - 100 - 0.25 * 465
    assert dc.step_allowance(480, 100.0, "agreement") == pytest.approx(248.75)
    # the last step gets everything left
    assert dc.step_allowance(480, 400.0, "throughput") == pytest.approx(65.0)
    # over budget: nothing, never negative
    assert dc.step_allowance(480, 470.0, "throughput") == 0.0
    # a subset of steps shares the budget among itself: agreement 0.25 / (0.25 + 0.25)
    assert dc.step_allowance(480, 0.0, "agreement", ("agreement", "throughput")) == pytest.approx(232.5)


def test_affordable_rods_shrinks_by_three_in_whole_tiles():
    cost = lambda n: n * 1e-3  # noqa: E731 - 1 ms per rod
    assert dc.affordable_rods(100000, 200.0, cost) == 100000
    # 100 s: 100000 -> 33300 (whole tiles) fits
    assert dc.affordable_rods(100000, 40.0, cost) == 33300
    # 20 s: 33300 -> 11100 fits
    assert dc.affordable_rods(100000, 20.0, cost) == 11100
    # nothing above the previous size fits
    assert dc.affordable_rods(100000, 5.0, cost, floor=10100) is None
    # nothing to predict from yet: the size is tried while any time is left
    assert dc.affordable_rods(1000, 1.0, lambda n: None) == 1000
    assert dc.affordable_rods(1000, 0.0, lambda n: None) is None


def test_distances_in_diameters():
    a = np.zeros((4, 3))
    b = np.zeros((4, 3))
    b[1] = (0.003, 0.004, 0.0)  # 5 mm
    b[2] = (0.0, 0.0, 0.02)  # 20 mm
    b[3] = (1e-12, 0.0, 0.0)  # round-off
    d = dc.distances(a, b, diameter=0.01)
    assert d["max_m"] == pytest.approx(0.02)
    assert d["max_d"] == pytest.approx(2.0)
    assert d["median_d"] == pytest.approx(0.25)  # median of 0, 1e-10, 0.5, 2 diameters
    assert d["fraction_within"] == pytest.approx(0.5)  # the first and the last within 1e-9 m
    assert d["p90_d"] == pytest.approx(np.percentile([0, 1e-10, 0.5, 2.0], 90))


def test_judge_kinds_and_the_late_checks():
    assert dc.judge("h", 1.0, 1.005, "relative", 0.01)["ok"]
    assert not dc.judge("h", 1.0, 1.02, "relative", 0.01)["ok"]
    assert dc.judge("Z", 2.6, 2.4, "absolute", 0.3)["difference"] == pytest.approx(0.2)
    assert not dc.judge("Z", 2.6, 2.2, "absolute", 0.3)["ok"]
    assert not dc.judge("x", 0.0, 2e-9, "bound", 1e-9)["ok"]
    assert dc.judge("x", 0.0, 5e-10, "bound", 1e-9)["ok"]
    with pytest.raises(ValueError):
        dc.judge("x", 0.0, 1.0, "squared", 1.0)
    # the CPU-only measurement the tolerances were set from passes them ...
    cpu = {"centroid_height": 1.08938, "contacts_per_rod": 2.6296, "kinetic_energy": 43.5418,
           "largest_cluster_fraction": 0.8463}
    other_order = {"centroid_height": 1.08921, "contacts_per_rod": 2.5556, "kinetic_energy": 43.3322,
                   "largest_cluster_fraction": 0.8481}
    checks = dc.late_checks(cpu, other_order, {"median_d": 0.0914})
    assert [c["name"] for c in checks] == list(dc.LATE_TOLERANCES)
    assert all(c["ok"] for c in checks)
    # ... a pile that lost its contacts and scattered does not
    broken = dict(other_order, contacts_per_rod=1.9, kinetic_energy=60.0)
    failed = {c["name"] for c in dc.late_checks(cpu, broken, {"median_d": 0.8}) if not c["ok"]}
    assert failed == {"contacts_per_rod", "kinetic_energy", "median_vertex_distance_d"}


def test_junit_counts():
    xml = """<?xml version="1.0" encoding="utf-8"?><testsuites><testsuite name="pytest" tests="4">
    <testcase classname="tests.test_devices" name="test_a" time="1.0"/>
    <testcase classname="tests.test_devices" name="test_b" time="1.0"><failure message="x">tb</failure></testcase>
    <testcase classname="tests.test_fields" name="test_c" time="0.1"><skipped message="no CUDA"/></testcase>
    <testcase classname="tests.test_fields" name="test_d" time="0.1"><error message="y">tb</error></testcase>
    </testsuite></testsuites>"""
    c = dc.junit_counts(xml)
    assert (c["tests"], c["passed"], c["failed"], c["errors"], c["skipped"]) == (4, 1, 1, 1, 1)
    assert c["not_passed"] == ["tests.test_devices::test_b", "tests.test_fields::test_d"]


def test_markdown_of_a_record_with_a_failed_step():
    rec = {"command": "scripts/device_check.sh", "date": "2026-12-05T00:00:00+00:00", "budget_s": 480.0,
           "wall_s": 12.0, "complete": True, "problems": ["agreement failed: RuntimeError: boom"],
           "device": {"warp_device": "cuda:0", "name": "GPU", "arch": "sm_90", "memory_gib": 79.1,
                      "cuda_driver": "12.4", "cuda_toolkit_of_warp": "12.8", "nvidia_smi": None},
           "versions": {"warp": "1.19.0", "rodwarp": "0.1.0", "cpu": "CPU", "git": {"commit": "abc"}},
           "steps": {"cuda_tests": {"command": "pytest -m cuda tests/", "wall_s": 10.0, "allowance_s": 232.5,
                                    "counts": {"passed": 3, "failed": 0, "errors": 0, "skipped": 0,
                                               "not_passed": []}, "ok": True},
                     "agreement": {"ok": False, "error": "RuntimeError: boom"}}}
    md = dc.markdown(rec)
    assert "3 passed, 0 failed" in md
    assert "Step agreement failed: `RuntimeError: boom`" in md
    assert "## 2." not in md
