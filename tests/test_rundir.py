"""Output folders (issue 15): a run owns its folder through rodwarp-run.json; location problems
(a file, read-only, full disk) are refused before the work with the path, exit 2; old and new
outputs never mix; hidden temporaries are cleaned."""

from __future__ import annotations

import errno
import json
import os
import subprocess
import uuid
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from rodwarp.cli import app
from rodwarp.experiments import default_run_name
from rodwarp.rodset.rundir import MANIFEST

runner = CliRunner()
SHORT = ["simulate", "--alpha", "20", "--n-rods", "12", "--entangle-duration", "0.02", "--duration", "0.02",
         "--save-every", "0.01", "--checkpoint-every", "0.01", "--device", "cpu", "--quiet"]


def _err(res):
    lines = [ln for ln in res.output.strip().splitlines() if ln.strip() and "CUDA" not in ln]
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    return lines[0]


def _manifest(d):
    return json.loads((d / MANIFEST).read_text())


def test_out_is_a_file_or_under_a_file(tmp_path):
    f = tmp_path / "afile"
    f.write_text("x")
    res = runner.invoke(app, [*SHORT, "--out", str(f)])
    assert res.exit_code == 2 and str(f) in _err(res) and "is a file" in _err(res)
    res = runner.invoke(app, [*SHORT, "--out", str(f / "run")])
    assert res.exit_code == 2 and "is a file" in _err(res)
    assert f.read_text() == "x"


def test_read_only_location_is_refused_before_work(tmp_path, monkeypatch):
    # root ignores permission bits, so a read-only file system is mocked at the probe write
    from rodwarp import validation

    def ro(directory):
        raise OSError(errno.EROFS, "Read-only file system")

    monkeypatch.setattr(validation, "probe_write", ro)
    from rodwarp.rodset import RodSet

    s = np.linspace(-0.5, 0.5, 10)
    RodSet.from_polylines([np.stack([s, 0 * s, 0 * s + 0.1], 1)], radii=0.01).save(tmp_path / "rods.npz")
    out = tmp_path / "ro" / "run"
    for args in (SHORT, ["analyze", str(tmp_path / "rods.npz")], ["sweep", "--alpha", "20", "--freq", "1"]):
        res = runner.invoke(app, [*args, "--out", str(out)])
        line = _err(res)
        assert res.exit_code == 2 and "read-only" in line and str(out) in line, line
    assert not out.exists()


def test_write_failure_names_the_file(tmp_path):
    from rodwarp.rodset.files import atomic_path

    target = tmp_path / "summary.json"
    with pytest.raises(OSError) as e:
        with atomic_path(target) as tmp:
            tmp.write_text("partial")
            raise OSError(errno.ENOSPC, "No space left on device")
    assert e.value.filename == str(target) and e.value.errno == errno.ENOSPC
    assert list(tmp_path.iterdir()) == []  # no torn file, no temporary left


def test_disk_full_during_the_run_names_the_file_and_keeps_earlier_results(tmp_path, monkeypatch):
    # a mocked failure of the 4th VTK frame (a full disk); the CLI prints the path, exit 2, and
    # the frames and metrics written before are readable
    import rodwarp.rodset.trajectory as outputs

    real = outputs.write_vtp
    calls = []

    def failing(path, *a, **k):
        calls.append(path)
        if len(calls) == 4:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return real(path, *a, **k)

    monkeypatch.setattr(outputs, "write_vtp", failing)
    out = tmp_path / "run"
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    line = _err(res)
    assert res.exit_code == 2 and "No space left on device" in line and "frame_00003.vtp" in line
    import zarr

    g = zarr.open_group(str(out / "trajectory.zarr"), mode="r")
    assert g.attrs["n_frames"] == 4 and np.isfinite(g["positions"][:3]).all()
    m = _manifest(out)
    assert m["complete"] is False and m["status"] == "failed" and "No space left" in m["error"]
    assert not (out / "final.npz").exists()


def _mount_tmpfs(path, size):
    path.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({r.stderr.decode().strip()[:80]})")


def test_real_small_tmpfs_full_before_and_during_the_run(tmp_path, monkeypatch):
    mnt = tmp_path / "small"
    _mount_tmpfs(mnt, "2m")  # the short run writes about 450 kB; its estimate is 1.1 MB
    try:
        # before: a run whose estimate exceeds the free space is refused at once, with the path
        res = runner.invoke(app, [*SHORT, "--n-rods", "200", "--duration", "1", "--out", str(mnt / "big")])
        line = _err(res)
        assert res.exit_code == 2 and "on disk" in line and "is free at" in line and str(mnt) in line
        assert not (mnt / "big").exists()
        # during: the estimate fits, then something else fills the disk after the third frame;
        # the real ENOSPC is reported with the file it hit
        import rodwarp.rodset.trajectory as outputs

        real, n = outputs.write_vtp, []

        def fill_then_write(path, *a, **k):
            n.append(path)
            if len(n) == 3:
                with open(mnt / "ballast", "wb") as fh:
                    try:
                        while True:
                            fh.write(b"\0" * 65536)
                    except OSError:
                        pass
            return real(path, *a, **k)

        monkeypatch.setattr(outputs, "write_vtp", fill_then_write)
        res = runner.invoke(app, [*SHORT, "--out", str(mnt / "run")])
        line = _err(res)
        assert res.exit_code == 2 and "cannot write" in line and str(mnt / "run") in line
        assert _manifest(mnt / "run")["complete"] is False
        import zarr

        assert zarr.open_group(str(mnt / "run" / "trajectory.zarr"), mode="r").attrs["n_frames"] >= 2
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)


def test_stale_run_refused_then_overwritten_cleanly(tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    assert res.exit_code == 0, res.output
    first = _manifest(out)
    assert first["complete"] is True and first["kind"] == "simulate"
    assert {"summary.json", "final.npz", "trajectory.zarr"} <= set(first["present"])
    # debris that must not survive into the next run, and a user's own file that must
    (out / "vtk" / "frame_09999.vtp").write_text("old frame")
    (out / ".summary.json.abc123.tmp").write_text("torn")
    (out / "vtk" / ".frame_00001.vtp.x.tmp").write_text("torn")
    (out / "notes.txt").write_text("mine")

    res = runner.invoke(app, [*SHORT, "--seed", "1", "--out", str(out)])
    line = _err(res)
    assert res.exit_code == 2 and "holds a finished simulate run" in line and "--overwrite" in line
    assert (out / "vtk" / "frame_09999.vtp").exists()  # a refusal touches nothing

    res = runner.invoke(app, [*SHORT, "--seed", "1", "--out", str(out), "--resume"])
    assert res.exit_code == 2 and "nothing to resume" in _err(res)

    res = runner.invoke(app, [*SHORT, "--seed", "1", "--out", str(out), "--overwrite"])
    assert res.exit_code == 0, res.output
    second = _manifest(out)
    assert second["run_id"] != first["run_id"] and second["complete"] and second["parameters"]["seed"] == 1
    assert not (out / "vtk" / "frame_09999.vtp").exists()
    assert not (out / ".summary.json.abc123.tmp").exists() and not (out / "vtk" / ".frame_00001.vtp.x.tmp").exists()
    assert (out / "notes.txt").read_text() == "mine"
    assert json.loads((out / "summary.json").read_text())["seed"] == 1
    pvd = (out / "trajectory.pvd").read_text()
    assert sorted(p.name for p in (out / "vtk").iterdir()) == sorted(
        ln.split('file="vtk/')[1].split('"')[0] for ln in pvd.splitlines() if 'file="' in ln)


def test_failed_run_is_recorded_and_named(tmp_path, monkeypatch):
    # a run that failed after writing outputs keeps them and its cause; the rerun is refused
    # (--overwrite replaces it; --resume is not offered without a checkpoint). A failed start
    # that wrote nothing does not block the rerun: tests/test_ownership.py
    from rodwarp.errors import RodwarpError
    from rodwarp.experiments import _protocol as protocol

    def stop(*a, **k):
        raise RodwarpError("stopped for the test after the initial packing")

    out = tmp_path / "run"
    with monkeypatch.context() as mp:
        mp.setattr(protocol, "_default_dt", stop)
        res = runner.invoke(app, [*SHORT, "--out", str(out)])
    assert res.exit_code == 2 and "stopped for the test" in _err(res)
    m = _manifest(out)
    assert m["status"] == "failed" and "stopped for the test" in m["error"] and (out / "initial.npz").exists()
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    line = _err(res)
    assert res.exit_code == 2 and "holds a failed simulate run" in line and "stopped for the test" in line
    assert "--resume" not in line
    # a refused claim leaves the other run's record alone
    assert _manifest(out)["run_id"] == m["run_id"]


def test_analyze_replaces_its_own_analysis_but_not_another_run(tmp_path):
    run = tmp_path / "run"
    assert runner.invoke(app, [*SHORT, "--out", str(run)]).exit_code == 0
    a = run / "analysis"
    res = runner.invoke(app, ["analyze", str(run), "--quiet", "--no-figures"])
    assert res.exit_code == 0, res.output
    (a / ".fields.zarr.dead.tmp").mkdir()
    (a / "histograms.png").write_text("a figure of an older analysis")
    res = runner.invoke(app, ["analyze", str(run), "--quiet", "--no-figures", "--radius", "0.2"])
    assert res.exit_code == 0, res.output
    s = json.loads((a / "summary.json").read_text())
    assert s["radius"] == pytest.approx(0.2)
    import zarr

    assert zarr.open_group(str(a / "fields.zarr"), mode="r").attrs["radius"] == pytest.approx(0.2)
    assert not (a / "histograms.png").exists() and not (a / ".fields.zarr.dead.tmp").exists()
    m = _manifest(a)
    assert m["kind"] == "analyze" and m["complete"] and m["parameters"]["radius"] == pytest.approx(0.2)
    # into the simulation's own folder: refused, the simulation untouched
    res = runner.invoke(app, ["analyze", str(run), "--out", str(run), "--quiet"])
    assert res.exit_code == 2 and "holds a finished simulate run" in _err(res)
    assert (run / "final.npz").exists() and _manifest(run)["kind"] == "simulate"


def test_default_folder_names_every_distinguishing_parameter():
    from rodwarp.experiments import ProtocolParams

    base = default_run_name(ProtocolParams())
    assert base == "alpha100_freq10_g0.5_seed0"
    names = {default_run_name(ProtocolParams(seed=1)), default_run_name(ProtocolParams(gravity=2.0)),
             default_run_name(ProtocolParams(amplitude=0.002)), default_run_name(ProtocolParams(static_load=1.0)),
             default_run_name(ProtocolParams(dt=1e-3)), default_run_name(ProtocolParams(box=(2.0, 2.0, 2.5))),
             default_run_name(ProtocolParams(n_rods=100)), base}
    assert len(names) == 8
    assert "seed1" in default_run_name(ProtocolParams(seed=1)) and "_g2_" in default_run_name(ProtocolParams(gravity=2))
    long = ProtocolParams(**{f: 1.2345678 for f in ("amplitude", "duration", "entangle_duration", "entangle_freq",
                                                     "entangle_amplitude", "static_load", "mu", "young", "density",
                                                     "save_every", "checkpoint_every")})
    assert len(default_run_name(long)) <= 130


def test_manifest_is_written_first(tmp_path, monkeypatch):
    # the folder is taken before the work: a run stopped at its first step already owns it
    from rodwarp.experiments import _protocol as protocol
    from rodwarp.errors import RodwarpError

    def stop(*a, **k):
        raise RodwarpError("stopped for the test")

    monkeypatch.setattr(protocol, "_default_dt", stop)
    out = tmp_path / "run"
    res = runner.invoke(app, [*SHORT, "--out", str(out)])
    assert res.exit_code == 2
    m = _manifest(out)
    assert m["complete"] is False and m["kind"] == "simulate" and uuid.UUID(m["run_id"])
    assert m["parameters"]["n_rods"] == 12 and os.path.exists(out / "initial.npz")


def test_the_run_folder_layer_knows_no_command():
    """The commands' folder contracts are one table of data (rodset/commands.py); rundir itself
    names no command (no string literal outside docstrings is a command's name), and importing
    it alone, with no command's module, knows every command's contract."""
    import ast

    from rodwarp.rodset import rundir

    tree = ast.parse(Path(rundir.__file__).read_text())
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef)) and n.body
                  and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    literals = {n.value for n in ast.walk(tree)
                if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings}
    assert not literals & {"simulate", "analyze", "segment", "sweep", "phantom", "phase-diagram"}
    import subprocess
    import sys

    code = ("import sys; from rodwarp.rodset import rundir; "
            "print(sorted(rundir.OUTPUTS), any(m.startswith(('rodwarp.experiments', 'rodwarp.analysis', "
            "'rodwarp.ct')) for m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "['analyze', 'phase-diagram', 'segment', 'simulate', 'sweep'] False"
