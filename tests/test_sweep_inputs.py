"""A sweep's inputs are refused, not silently changed (issue 47): --workers beyond the machine's
cores or memory, a --set of an option the sweep owns, an empty or repeated list item, a --set
key given twice. Each refusal is exit 2 with one 'error:' line naming the cause and the fix,
before any cluster starts or anything is written."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from rodwarp.cli import app
from rodwarp.errors import RodwarpError
from rodwarp.experiments import SweepSpec, points
from rodwarp.experiments import _sweep

runner = CliRunner()

TINY = ["sweep", "--alpha", "20", "--freq", "1", "--entangle-duration", "0.02", "--duration", "0.02",
        "--save-every", "0.01", "--device", "cpu", "--quiet", "--no-figures", "--set", "n_rods=12"]


def refused(args, *fragments, out=None):
    """The CLI exits 2 with one 'error:' line holding every fragment, and writes nothing in ``out``."""
    res = runner.invoke(app, args)
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]
    assert res.exit_code == 2, res.output
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    for f in fragments:
        assert f in lines[0], lines[0]
    assert out is None or not out.exists()
    return lines[0]


@pytest.fixture
def machine(monkeypatch):
    """A machine of ``cores`` usable cores and ``memory`` bytes available (set by the test)."""
    import rodwarp.validation

    box = {"cores": 2, "memory": 64e9}
    monkeypatch.setattr(_sweep, "usable_cores", lambda: box["cores"])
    monkeypatch.setattr(rodwarp.validation, "available_memory", lambda: box["memory"])
    return box


# ------------------------------------------------------------------------------ --workers

def test_more_workers_than_cores_is_refused(tmp_path, machine):
    out = tmp_path / "sw"
    refused([*TINY, "--workers", "1000", "--out", str(out)],
            "--workers 1000 is more than this machine's 2 cores", "use --workers 2 or fewer", out=out)


def test_more_workers_than_memory_holds_is_refused(tmp_path, machine):
    need = _sweep.check_points(points(SweepSpec(alphas=[20.0], freqs=[1.0], entangle_duration=0.02,
                                                duration=0.02, device="cpu",
                                                overrides={"n_rods": 12, "save_every": 0.01})), local=False)
    machine.update(cores=8, memory=2.5 * need)  # two points' memory, eight cores
    out = tmp_path / "sw"
    line = refused([*TINY, "--workers", "3", "--out", str(out)], "--workers 3 is more than what the",
                   "of memory available holds", "use --workers 2 or fewer", out=out)
    assert "cores" not in line.split(";")[0]


@pytest.mark.parametrize("n", ["0", "-3"])
def test_fewer_than_one_worker_is_refused(tmp_path, n):
    refused([*TINY, "--workers", n, "--out", str(tmp_path / "sw")], f"--workers must be >= 1, got {n}")


def test_default_workers_are_the_limit(machine):
    machine.update(cores=3, memory=64e9)
    assert _sweep.local_workers(None, 1e9) == 3
    machine.update(memory=2.5e9)
    assert _sweep.local_workers(None, 1e9) == 2  # memory for two points of 1 GB
    assert _sweep.local_workers(1, 1e9) == 1
    with pytest.raises(RodwarpError, match="use --workers 2 or fewer"):
        _sweep.local_workers(3, 1e9)


def test_usable_cores_are_the_affinity():
    import os

    assert _sweep.usable_cores() == len(os.sched_getaffinity(0))


# ------------------------------------------------------------------------------ --set of the sweep's own options

@pytest.mark.parametrize("item, fragments", [
    ("out=x", ["--set out: a sweep writes each point into its own folder under the sweep's --out",
               "give --out to the sweep"]),
    ("resume=true", ["--set resume: a sweep resumes by itself", "run the same `rodwarp sweep` command again"]),
    ("overwrite=true", ["--set overwrite: use the sweep's own --overwrite"]),
    ("quiet=true", ["--set quiet: use the sweep's own --quiet"]),
    ("entangled_from=runs/a", ["--set entangled_from: a sweep shares the entangled packing", "--share-entangling"]),
    ("entangled-from=runs/a", ["--set entangled_from:"]),
    ("initial=rods.npz", ["--set initial: a sweep always starts each point from a random packing",
                          "rodwarp simulate --initial FILE"]),
    ("diameter=0.001", ["--set diameter: it describes an --initial rod set", "random packing"]),
    ("units=mm", ["--set units: it describes an --initial rod set"]),
    ("alpha=30", ["--set alpha: alpha is set by the sweep itself", "give the sweep's --alpha"]),
    ("static-load=1", ["--set static_load:", "give the sweep's --static-load"]),
    ("seed=3", ["--set seed:", "--seeds N"]),
    ("duration=1", ["--set duration:", "give the sweep's --duration"]),
    ("device=cpu", ["--set device:", "give the sweep's --device"]),
])
def test_set_of_an_option_the_sweep_owns_names_the_sweeps_own(tmp_path, item, fragments):
    out = tmp_path / "sw"
    line = refused([*TINY, "--set", item, "--out", str(out)], *fragments, out=out)
    assert "no such simulate parameter" not in line
    if item.startswith("initial"):
        assert "set by the sweep" not in line  # the sweep sets no rod set: it makes a random packing


def test_overrides_of_the_api_say_the_same():
    with pytest.raises(RodwarpError, match="override initial: a sweep always starts each point from a random"):
        points(SweepSpec(alphas=[20.0], freqs=[1.0], overrides={"initial": "rods.npz"}))
    with pytest.raises(RodwarpError, match="override out: a sweep writes each point"):
        points(SweepSpec(alphas=[20.0], freqs=[1.0], overrides={"out": "x"}))


def test_unknown_set_key_still_points_to_simulate_help(tmp_path):
    refused([*TINY, "--set", "nope=1", "--out", str(tmp_path / "sw")], "--set nope: no such simulate parameter")


# ------------------------------------------------------------------------------ list items never dropped

@pytest.mark.parametrize("option, value, fragment", [
    ("--alpha", "25,,50", "--alpha 25,,50: item 2 of 3 is empty"),
    ("--alpha", "25,50,", "--alpha 25,50,: item 3 of 3 is empty"),
    ("--alpha", ",25", "--alpha ,25: item 1 of 2 is empty"),
    ("--freq", "1, ,10", "--freq 1, ,10: item 2 of 3 is empty"),
    ("--gravity", "0.5,,10", "--gravity 0.5,,10: item 2 of 3 is empty"),
    ("--static-load", "0,,1", "--static-load 0,,1: item 2 of 3 is empty"),
    ("--alpha", "25,50,25", "--alpha 25,50,25: 25 is given twice"),
    ("--freq", "1,1.0", "--freq 1,1.0: 1 is given twice"),
])
def test_empty_or_repeated_grid_item_is_refused(tmp_path, option, value, fragment):
    out = tmp_path / "sw"
    refused([*TINY, option, value, "--out", str(out)], fragment, out=out)


def test_set_key_given_twice_is_refused(tmp_path):
    out = tmp_path / "sw"
    refused([*TINY, "--set", "n_rods=13", "--out", str(out)],
            "--set n_rods is given twice (n_rods=12 and n_rods=13); give each parameter once", out=out)
    refused([*TINY, "--set", "rod-model=rigid", "--set", "rod_model=elastic", "--out", str(out)],
            "--set rod_model is given twice", out=out)


def test_save_every_given_both_ways_is_refused(tmp_path):
    out = tmp_path / "sw"
    refused([*TINY, "--set", "save_every=0.02", "--out", str(out)],
            "--save-every 0.01 and --set save_every=0.02 both given", out=out)


def test_set_strains_with_an_empty_item_is_refused(tmp_path):
    refused([*TINY, "--set", "strains=0,,0.1", "--out", str(tmp_path / "sw")],
            "--set strains 0,,0.1: item 2 of 3 is empty")


def test_simulate_strains_with_an_empty_item_is_refused(tmp_path):
    out = tmp_path / "run"
    for value, fragment in (("0,,0.1", "--strains 0,,0.1: item 2 of 3 is empty"),
                            ("0,0.1,", "--strains 0,0.1,: item 3 of 3 is empty")):
        refused(["simulate", "--protocol", "lab", "--strains", value, "--out", str(out), "--quiet"], fragment,
                out=out)


def test_strains_parse_as_before():
    from rodwarp.cli import _parse_strains

    assert _parse_strains("") == () and _parse_strains(" ") == ()
    assert _parse_strains("0, 0.05,0.1") == (0.0, 0.05, 0.1)
    with pytest.raises(RodwarpError, match="--strains must be comma-separated numbers"):
        _parse_strains("0,x")
