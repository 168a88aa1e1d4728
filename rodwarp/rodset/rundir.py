"""Output folders owned by one run: a manifest written first and completed last.

``rodwarp-run.json`` in an output folder says which run the folder belongs to: the command
kind (``simulate``, ``analyze``), a run id, every parameter, the outputs the run writes, and
``complete`` (false while the run is going, true once its last output is written). Rules:

* a new run in a folder holding another run (a manifest, or outputs of a run from before
  manifests) is refused unless ``overwrite``, which first takes the folder over (a new
  incomplete manifest) and then removes the old run's outputs, so old and new never mix;
* ``resume`` continues only the folder's own unfinished run of the same parameters;
* an analysis replaces an earlier analysis in its folder (it is a pure function of its
  input and options, recorded in the manifest), but never another kind of run;
* hidden temporary files left by a killed writer (``.NAME.*.tmp``, ``.NAME.old``) are removed
  when a run takes the folder;
* location problems (the path is a file, a read-only or full file system, too little free
  space for the run's estimate) are refused before any work, with the path.
"""

from __future__ import annotations

import json
import os
import shutil
import socket
import sys
import time
import uuid
from pathlib import Path

from rodwarp.errors import RodwarpError
from rodwarp.rodset.files import write_json
from rodwarp.validation import disk_fits, output_location

MANIFEST = "rodwarp-run.json"
FORMAT = "rodwarp-run"

#: what ``rodwarp simulate`` writes in its folder (``analysis`` is a later analyze run of it)
SIMULATE_OUTPUTS = ("summary.json", "metrics.csv", "metrics.png", "trajectory.zarr", "trajectory.pvd", "vtk",
                    "initial.npz", "entangled.npz", "entangled_from.json", "final.npz", "snapshots.png",
                    "checkpoints", "analysis")
#: what ``rodwarp analyze`` writes in its folder
ANALYZE_OUTPUTS = ("fields.zarr", "summary.json", "rods.npz", "histograms.png", "slices.png", "zprofiles.png",
                   "tangles.png", "distributions.png")
#: outputs only a simulation writes (an analysis never replaces a folder holding them)
_SIMULATION_ONLY = ("final.npz", "trajectory.zarr", "metrics.csv", "checkpoints")
#: subfolders whose hidden temporary files are cleaned too
_TEMP_DIRS = ("", "vtk", "checkpoints")


def _read_manifest(path: Path):
    m = path / MANIFEST
    if not m.exists():
        return None
    try:
        data = json.loads(m.read_text())
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise ValueError("not a rodwarp manifest")
        return data
    except (OSError, ValueError):
        return {"format": FORMAT, "kind": "unknown", "complete": False, "unreadable": True, "outputs": []}


def _describe(m: dict) -> str:
    state = "a finished" if m.get("complete") else ("a failed" if m.get("status") == "failed" else "an unfinished")
    when = f", started {m['started']}" if m.get("started") else ""
    err = f" ({m['error'][:80]})" if m.get("status") == "failed" and m.get("error") else ""
    return f"{state} {m.get('kind', 'unknown')} run{when}{err}"


def _param_diff(a: dict, b: dict) -> list[str]:
    a = json.loads(json.dumps(a, default=str))
    b = json.loads(json.dumps(b, default=str))
    return sorted(k for k in set(a) | set(b) if k != "device" and a.get(k) != b.get(k))


def _remove(p: Path) -> None:
    if p.is_dir() and not p.is_symlink():
        shutil.rmtree(p)
    elif p.exists() or p.is_symlink():
        p.unlink()


def clean_temporaries(path: Path) -> list[Path]:
    """Remove hidden temporaries of interrupted atomic writes under ``path`` (and its ``vtk/``,
    ``checkpoints/``): ``.NAME.<random>.tmp`` files or folders and ``.NAME.old`` folders."""
    gone = []
    for sub in _TEMP_DIRS:
        d = path / sub if sub else path
        if not d.is_dir():
            continue
        for p in d.iterdir():
            if p.name.startswith(".") and (p.name.endswith(".tmp") or p.name.endswith(".old")):
                _remove(p)
                gone.append(p)
    return gone


#: folders this process took (path -> run id), so that only our own run is marked failed
_CLAIMED: dict = {}


def mark_failed(path, error: BaseException) -> None:
    """Record in the manifest that this process's run in ``path`` stopped with ``error``.

    Does nothing when this process did not take the folder (a refused claim leaves the other
    run's manifest alone)."""
    path = Path(path)
    key = str(path.resolve()) if path.exists() else None
    m = _read_manifest(path) if key else None
    if m is None or m.get("unreadable") or _CLAIMED.get(key) != m.get("run_id"):
        return
    m["status"] = "failed"
    m["error"] = " ".join(str(error).split())[:500]
    m["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    try:
        write_json(path / MANIFEST, m)
    except OSError:
        pass  # the error being reported matters more than its record


class RunDir:
    """An output folder taken by one run; see the module docstring for the rules.

    Use :func:`claim` to take a folder, and :meth:`complete` once the last output is written.
    """

    def __init__(self, path: Path, manifest: dict):
        self.path = path
        self.manifest = manifest

    @property
    def run_id(self) -> str:
        return self.manifest["run_id"]

    def _write(self) -> None:
        try:
            write_json(self.path / MANIFEST, self.manifest)
        except OSError as e:
            raise RodwarpError(f"cannot write {self.path / MANIFEST}: {e.strerror or e}; "
                               "free space or choose another --out") from None

    def complete(self, **extra) -> None:
        """Record the run as complete (its last act), with the outputs present and ``extra``."""
        self.manifest.update(extra)
        self.manifest["complete"] = True
        self.manifest["status"] = "complete"
        self.manifest["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        self.manifest["present"] = sorted(p.name for p in self.path.iterdir() if not p.name.startswith("."))
        self._write()


def claim(path, kind: str, parameters: dict, outputs, *, resume: bool = False, overwrite: bool = False,
          resumable: bool = False, replace_same_kind: bool = False, need_bytes: float = 0.0,
          name: str = "--out") -> RunDir:
    """Take the output folder ``path`` for a run, or refuse with one line saying why.

    Parameters
    ----------
    path : path-like
        The output folder (created).
    kind : str
        ``simulate`` or ``analyze``.
    parameters : dict
        Every parameter of the run (JSON-serialisable); compared on ``resume``.
    outputs : sequence of str
        Names of the files and folders the run writes in ``path``; with ``overwrite`` these
        (and those of the old manifest) are removed, never anything else.
    resume : bool
        Continue the folder's unfinished run of the same kind and parameters.
    overwrite : bool
        Replace whatever run the folder holds.
    resumable : bool
        The caller found something to resume (checkpoints); for folders from before manifests.
    replace_same_kind : bool
        Replace an earlier run of the same kind without ``overwrite`` (analyses).
    need_bytes : float
        Estimated disk space of the run (bytes), checked against the free space.
    name : str
        Option name used in messages.

    Returns
    -------
    RunDir
    """
    path = Path(path)
    output_location(path, name)
    if resume and overwrite:
        raise RodwarpError("--resume and --overwrite contradict each other: --resume continues the run in "
                           f"{path}, --overwrite replaces it; pass one")
    old = _read_manifest(path) if path.is_dir() else None
    present = [o for o in outputs if (path / o).exists()] if path.is_dir() else []
    run_id = None
    if resume:
        if old is None:
            if not resumable:
                raise RodwarpError(f"nothing to resume: {path} holds no unfinished {kind} run (no checkpoint); "
                                   "run without --resume")
        elif old.get("kind") != kind or old.get("unreadable"):
            raise RodwarpError(f"--resume continues only its own run: {path} holds {_describe(old)}; "
                               f"choose another --out")
        elif old.get("complete"):
            raise RodwarpError(f"nothing to resume: the {kind} run in {path} is finished; pass --overwrite to "
                               "run it again, or another --out")
        else:
            diff = _param_diff(parameters, old.get("parameters", {}))
            if diff:
                raise RodwarpError(f"--resume continues only its own run: the run in {path} has other "
                                   f"parameters ({', '.join(diff)}); repeat its original command with --resume, "
                                   f"or pass --overwrite to replace it")
            run_id = old.get("run_id")
    elif old is not None or present:
        same = old is not None and old.get("kind") == kind and not old.get("unreadable")
        if old is None and kind == "analyze":
            # an analysis from before manifests: its fields, and nothing of a simulation
            same = "fields.zarr" in present and not any((path / o).exists() for o in _SIMULATION_ONLY)
        if not (overwrite or (replace_same_kind and same)):
            what = _describe(old) if old is not None else f"outputs of an earlier run ({', '.join(present[:4])})"
            hint = " --resume to continue it," if old is not None and not old.get("complete") \
                and old.get("kind") == kind == "simulate" else ""
            raise RodwarpError(f"{path} holds {what}; pass --overwrite to replace it,{hint} or choose another "
                               f"{name}")
    if path.exists() and need_bytes > 0:
        # outputs about to be replaced free their space
        need = need_bytes - sum(_size(path / o) for o in present) if not resume else need_bytes
        disk_fits(path, need, f"this run's output ({name} {path})", "raise --save-every or free space")
    elif need_bytes > 0:
        disk_fits(path, need_bytes, f"this run's output ({name} {path})", "raise --save-every or free space")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise RodwarpError(f"cannot create {name} {path}: {e.strerror or e}; choose another location") from None
    manifest = {
        "format": FORMAT, "version": 1, "kind": kind, "run_id": run_id or uuid.uuid4().hex,
        "complete": False, "status": "running",
        "started": (old or {}).get("started") if run_id else time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "resumed": ((old or {}).get("resumed", 0) + 1) if run_id else 0,
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]),
        "host": socket.gethostname(), "pid": os.getpid(),
        "parameters": json.loads(json.dumps(parameters, default=str)),
        "outputs": list(outputs),
    }
    from rodwarp import __version__

    manifest["rodwarp"] = __version__
    run = RunDir(path, manifest)
    _CLAIMED[str(path.resolve())] = manifest["run_id"]
    # the folder is taken (new incomplete manifest) before the old outputs go, so a kill in
    # between leaves an incomplete run, never old outputs passing for the new run's
    run._write()
    if not resume:
        stale = set(present) | set((old or {}).get("outputs", []))
        for o in sorted(stale):
            p = path / o
            if o == "analysis" and p.is_dir() and not (p / MANIFEST).exists() and not (p / "summary.json").exists():
                continue  # not an analysis folder of ours
            if o != MANIFEST and (p.exists() or p.is_symlink()):
                _remove(p)
    clean_temporaries(path)
    return run


def _size(p: Path) -> int:
    if p.is_file():
        return p.stat().st_size
    total = 0
    if p.is_dir():
        for root, _, files in os.walk(p):
            for f in files:
                try:
                    total += os.path.getsize(os.path.join(root, f))
                except OSError:
                    pass
    return total
