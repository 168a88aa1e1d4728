"""Folders inside folders, and messages that name the real cause (issue 47).

A run is never written inside another run's folder (whose ``--overwrite`` would delete it), an
analysis never inside a run's own outputs, and an input is never among the outputs that
``--overwrite`` deletes before the run starts.
"""

from __future__ import annotations

import json

import pytest

from rodwarp.cli import main

TINY = ["--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02", "--save-every",
        "0.01", "--device", "cpu", "--quiet"]
LAB = ["--protocol", "lab", "--alpha", "20", "--n-rods", "30", "--pour-duration", "0.05", "--lift-duration", "0",
       "--duration", "0.04", "--save-every", "0.02", "--device", "cpu", "--quiet"]


def _run(args, capsys):
    rc = main([str(a) for a in args])
    cap = capsys.readouterr()
    err = [ln for ln in cap.err.splitlines() if ln.strip() and not ln.startswith(("note:", "warning:"))]
    return rc, err


def refused(args, capsys, *fragments) -> str:
    rc, err = _run(args, capsys)
    assert rc == 2 and len(err) == 1 and err[0].startswith("error:"), (rc, err)
    for f in fragments:
        assert f in err[0], err[0]
    return err[0]


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """A finished paper run and a finished lab run."""
    d = tmp_path_factory.mktemp("folders")
    assert main(["simulate", *TINY, "--out", str(d / "R")]) == 0
    assert main(["simulate", *LAB, "--checkpoint-every", "0.02", "--out", str(d / "L")]) == 0
    return d


def _fingerprint(folder):
    return sorted((str(p.relative_to(folder)), p.stat().st_size, p.stat().st_mtime_ns)
                  for p in folder.rglob("*") if p.is_file())


def test_an_input_among_the_outputs_overwrite_deletes_is_refused(runs, tmp_path, capsys):
    import shutil

    r = tmp_path / "R"
    shutil.copytree(runs / "R", r)
    before = _fingerprint(r)
    refused(["simulate", "--initial", r / "final.npz", "--duration", "0.02", "--save-every", "0.01", "--device",
             "cpu", "--quiet", "--overwrite", "--out", r], capsys, "lies in", "deletes first (final.npz)",
            "copy the input out")
    assert _fingerprint(r) == before  # nothing deleted


def test_a_run_inside_another_runs_folder_is_refused(runs, capsys):
    before = _fingerprint(runs / "R")
    refused(["simulate", *TINY, "--out", runs / "R" / "inner"], capsys, "in the folder of another run",
            "holds a finished simulate run")
    refused(["analyze", runs / "L", "--quiet", "--no-figures", "--out", runs / "R" / "an"], capsys,
            "in the folder of another run")
    assert _fingerprint(runs / "R") == before and not (runs / "R" / "inner").exists()


def test_an_analysis_inside_a_runs_checkpoints_is_refused(runs, capsys):
    before = _fingerprint(runs / "R")
    refused(["analyze", runs / "R", "--quiet", "--no-figures", "--out", runs / "R" / "checkpoints"], capsys,
            "checkpoints, an output of another run")
    assert _fingerprint(runs / "R") == before


def test_an_analysis_of_the_run_beside_it_is_allowed(runs, capsys):
    rc, err = _run(["analyze", runs / "R", "--quiet", "--no-figures"], capsys)
    assert rc == 0, err
    assert (runs / "R" / "analysis" / "summary.json").is_file()


def test_entangled_from_with_a_poured_protocol_names_the_protocol(runs, tmp_path, capsys):
    refused(["simulate", *LAB, "--entangled-from", runs / "R", "--out", tmp_path / "o"], capsys,
            "--entangled-from applies only with --protocol paper", "--protocol lab pours its packing")


def test_resuming_a_lab_run_with_paper_options_says_it_is_a_lab_run(runs, tmp_path, capsys):
    import shutil

    lab = tmp_path / "L"
    shutil.copytree(runs / "L", lab)
    m = json.loads((lab / "rodwarp-run.json").read_text())
    m.update(complete=False, status="failed")  # as a killed run leaves it
    (lab / "rodwarp-run.json").write_text(json.dumps(m))
    assert any((lab / "checkpoints").glob("ckpt_*.npz"))
    refused(["simulate", *TINY, "--resume", "--out", lab], capsys,
            "it holds a --protocol lab run, this command asks for --protocol paper")


def test_fill_height_and_n_rods_together_are_refused(tmp_path, capsys):
    refused(["simulate", "--protocol", "lab", "--fill-height", "2", "--n-rods", "40", "--out", tmp_path / "o"], capsys,
            "--fill-height and --n-rods both set")
