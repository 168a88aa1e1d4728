"""Output folders owned by one command run: a manifest written first and completed last.

``rodwarp-run.json`` in an output folder says which run the folder belongs to: the command
(``simulate``, ``analyze``, ``segment``, ``sweep``), a run id, every parameter, the outputs
the run writes, and ``complete`` (false while the run is going, true once its last output is
written). One rule for every command that writes a folder:

* the manifest's ``outputs`` are bare names from the command's own fixed list, declared in
  one table of data (:data:`rodwarp.rodset.commands.COMMANDS`, read into :data:`OUTPUTS`):
  this module names no command, and importing a command's module registers nothing; a
  manifest naming anything else (an absolute path, ``..``, a
  subfolder, a name no command writes, an unknown command) makes the folder *refused*,
  whatever the options: rodwarp deletes only names it wrote itself, inside the folder;
* a new run in a folder holding another run (a manifest, or outputs of a run from before
  manifests) is refused unless ``overwrite``, which first takes the folder over (a new
  incomplete manifest) and then removes the old run's outputs, so old and new never mix;
* ``resume`` continues only the folder's own unfinished run of the same parameters;
* ``replace_same_kind`` (analyze, segment): a run replaces an earlier run of its own command
  (a pure function of its input and options, recorded in the manifest), never another's;
* ``append`` (sweep): a run continues the folder's run of the same command and parameters
  (a sweep adds points of the same protocol), and is refused, naming the parameters that
  differ, when the parameters differ;
* a run that failed or was killed before writing any output (a failed start: no GPU, a
  packing that cannot be placed, a full disk) leaves nothing that blocks the corrected rerun:
  the next run of the same command takes the folder without ``overwrite``;
* hidden temporary files left by a killed writer (``.NAME.*.tmp``, ``.NAME.old``) are removed
  when a run takes the folder;
* location problems (the path is a file, a read-only or full file system, too little free
  space for the run's estimate) are refused before any work, with the path.
"""

from __future__ import annotations

import contextlib
import fnmatch
import json
import os
import shutil
import socket
import sys
import time
import uuid
from pathlib import Path

from rodwarp.errors import RodwarpError
from rodwarp.rodset.commands import COMMANDS
from rodwarp.rodset.files import write_json
from rodwarp.validation import disk_fits, output_location

MANIFEST = "rodwarp-run.json"
FORMAT = "rodwarp-run"

#: each command's outputs, as the command registered them (:func:`register_command`): the only
#: names a manifest of that command may list
OUTPUTS: dict[str, tuple] = {}
#: each command's other traits (:func:`register_command`)
_TRAITS: dict[str, dict] = {}


def register_command(kind: str, outputs, *, legacy_marker: str | None = None, exclusive=(),
                     resumable: bool = False, hosts: dict | None = None, inside_input: bool = False) -> None:
    """Declare a command's folder contract (:data:`rodwarp.rodset.commands.COMMANDS` holds
    every command's; a new command adds its row there).

    Parameters
    ----------
    kind : str
        The command's name, as manifests record it.
    outputs : sequence of str
        Every name it writes in its folder: bare names, or ``*`` patterns of bare names.
    legacy_marker : str, optional
        An output that marks a run of this command from before manifests (no other command's
        ``exclusive`` outputs beside it).
    exclusive : sequence of str
        Outputs only this command writes: a folder holding them is never taken for another
        command's legacy run.
    resumable : bool
        Its runs continue with ``--resume`` (suggested when a folder holds an unfinished one).
    hosts : dict, optional
        Output subfolder -> the kinds of runs it holds (a sweep's ``points``); runs of other
        kinds are never written inside this command's folder.
    inside_input : bool
        Its runs may be written inside the run folder they read (an analysis beside its run),
        though not inside that run's own outputs.
    """
    OUTPUTS[kind] = tuple(outputs)
    _TRAITS[kind] = {"legacy_marker": legacy_marker, "exclusive": tuple(exclusive), "resumable": bool(resumable),
                     "hosts": dict(hosts or {}), "inside_input": bool(inside_input)}
# every command's folder contract: one table of data (rodwarp.rodset.commands), read here
for _kind, _contract in COMMANDS.items():
    register_command(_kind, **_contract)


#: subfolders whose hidden temporary files are cleaned too
_TEMP_DIRS = ("", "vtk", "checkpoints")


def _is_bare(name) -> bool:
    """A plain file or folder name: no separator, not absolute, not ``.`` or ``..``."""
    return (isinstance(name, str) and name not in ("", ".", "..") and "/" not in name and "\\" not in name
            and "\0" not in name and not os.path.isabs(name))


def allowed_output(kind: str, name) -> bool:
    """``name`` is a bare name that a ``kind`` run writes in its folder (:data:`OUTPUTS`)."""
    return _is_bare(name) and any(fnmatch.fnmatchcase(name, pat) for pat in OUTPUTS.get(kind, ()))


def present_outputs(path: Path, outputs) -> list[str]:
    """The names of ``outputs`` (bare names or ``*`` patterns) that exist in ``path``."""
    path = Path(path)
    if not path.is_dir():
        return []
    names, entries = set(), None
    for o in outputs:
        if any(c in o for c in "*?["):
            if entries is None:
                entries = [p.name for p in path.iterdir()]
            names |= {n for n in entries if not n.startswith(".") and fnmatch.fnmatchcase(n, o)}
        elif (path / o).exists() or (path / o).is_symlink():
            names.add(o)
    return sorted(names)


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


def read_manifest(path) -> dict | None:
    """The manifest of the run folder ``path`` (None without one); see :func:`check_manifest`."""
    return _read_manifest(Path(path))


def check_manifest(path, m: dict | None, name: str = "--out") -> None:
    """Refuse a folder whose manifest names a command rodwarp does not have, or outputs that are
    not bare names of that command's own list: such a manifest (hand-edited, corrupted, from
    someone else) must never steer a deletion. Nothing is touched."""
    if m is None or m.get("unreadable"):
        return
    path = Path(path)
    kind = m.get("kind")
    if kind not in OUTPUTS:
        raise RodwarpError(f"{path / MANIFEST} names an unknown command '{kind}'; rodwarp changes nothing in "
                           f"{path}: check the folder, or choose another {name}")
    outputs = m.get("outputs", [])
    if not isinstance(outputs, list):
        outputs = [outputs]
    for o in outputs:
        if not allowed_output(kind, o):
            raise RodwarpError(f"{path / MANIFEST} lists {json.dumps(o) if isinstance(o, str) else repr(o)} among "
                               f"its outputs, which is not a file that rodwarp {kind} writes in its folder (a path outside "
                               f"it, or a hand-edited or corrupted manifest); rodwarp deletes nothing there: check "
                               f"the folder, or choose another {name}")


def _cause(text: str, limit: int = 160) -> str:
    """``text`` on one line, cut at a word boundary (with an ellipsis) when longer than ``limit``."""
    text = " ".join(str(text).split())
    if len(text) <= limit:
        return text
    cut = text[:limit].rsplit(" ", 1)[0].rstrip(",;:")
    return cut + " ..."


def _describe(m: dict) -> str:
    if m.get("unreadable"):
        return f"an unreadable {MANIFEST}"
    state = "a finished" if m.get("complete") else ("a failed" if m.get("status") == "failed" else "an unfinished")
    when = f", started {m['started']}" if m.get("started") else ""
    err = f" ({_cause(m['error'])})" if m.get("status") == "failed" and m.get("error") else ""
    return f"{state} {m.get('kind', 'unknown')} run{when}{err}"


def _param_diff(a: dict, b: dict) -> list[str]:
    a = json.loads(json.dumps(a, default=str))
    b = json.loads(json.dumps(b, default=str))
    return sorted(k for k in set(a) | set(b) if k != "device" and a.get(k) != b.get(k))


def _differences(was: dict, now: dict, diff: list[str]) -> str:
    """The first differences between two runs' parameters, ``k X there, Y here``; a different
    protocol first and by name, since the other differences follow from it."""
    first = [k for k in ("protocol", "kind") if k in diff]
    if first:
        k = first[0]
        return f"it holds a --{k} {was.get(k)} run, this command asks for --{k} {now.get(k)}"
    return "; ".join(f"{k} {_show(was.get(k))} there, {_show(now.get(k))} here" for k in diff[:4])


def _show(v) -> str:
    return "unset" if v is None else (f"{v:g}" if isinstance(v, float) else json.dumps(v, default=str))


def _alive(m: dict) -> bool:
    """The manifest's process is still running on this host (another run writes the folder)."""
    if m.get("complete") or m.get("status") != "running" or m.get("host") != socket.gethostname():
        return False
    pid = m.get("pid")
    if not isinstance(pid, int) or pid <= 0 or pid == os.getpid():
        return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, owned by someone else
        return True
    return True


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
        if not d.is_dir() or d.is_symlink():
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
    run's manifest alone). A run that wrote none of its outputs keeps its record (the cause),
    and the next run of the corrected command takes the folder without ``--overwrite``."""
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


@contextlib.contextmanager
def writing_part(path, part: str):
    """Mark a later part of a finished run (a sweep's phase diagram) as being written.

    The manifest of ``path`` records ``parts[part]`` with ``complete`` false before the part's
    files are written and true once they all are, so a kill while a part is rewritten leaves
    the folder saying which of its outputs are incomplete. A folder without a manifest (from
    before manifests) is written as before.
    """
    path = Path(path)
    m = _read_manifest(path)
    if m is None or m.get("unreadable"):
        yield
        return
    parts = m.setdefault("parts", {})
    parts[part] = {"complete": False, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "pid": os.getpid()}
    write_json(path / MANIFEST, m)
    try:
        yield
    except BaseException as e:
        m = _read_manifest(path) or m
        m.setdefault("parts", {}).setdefault(part, {}).update(status="failed", error=_cause(str(e), 500))
        try:
            write_json(path / MANIFEST, m)
        except OSError:
            pass  # the error being reported matters more than its record
        raise
    m = _read_manifest(path) or m
    m.setdefault("parts", {})[part] = {"complete": True, "finished": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
    write_json(path / MANIFEST, m)


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
        # finished: a later error in this process (another command's refusal) is not this run's
        _CLAIMED.pop(str(self.path.resolve()), None)


def _inside(child: Path, parent: Path) -> bool:
    """``child`` is ``parent`` or lies under it (both resolved)."""
    return child == parent or parent in child.parents


def _refuse_nested(path: Path, kind: str, inputs, name: str) -> None:
    """Refuse an output folder inside another run's folder: there that run's ``--overwrite``
    would delete it, or its outputs would mix with the run's. Allowed: a subfolder that the
    run's command hosts such runs in (``register_command``'s ``hosts``: a sweep's points, a
    run's analysis), and a command that may write inside the run it reads (``inside_input``),
    outside that run's own outputs (never in its ``checkpoints``)."""
    here = path.resolve()
    srcs = [Path(i).resolve() for i in inputs]
    for parent in here.parents:
        m = _read_manifest(parent) if (parent / MANIFEST).is_file() else None
        if m is None or m.get("unreadable"):
            continue
        first = here.relative_to(parent).parts[0]
        owner = m.get("kind")
        traits = _TRAITS.get(owner, {})
        if kind in traits.get("hosts", {}).get(first, ()):
            continue
        reads_it = _TRAITS.get(kind, {}).get("inside_input") and any(_inside(s, parent) for s in srcs)
        if reads_it and not allowed_output(owner, first):
            continue
        where = f"in {parent / first}, an output of" if allowed_output(owner, first) else "in the folder of"
        raise RodwarpError(f"{name} {path} lies {where} another run: {parent} holds {_describe(m)}, whose "
                           f"--overwrite would delete this {kind} run or mix with it; choose an {name} outside "
                           f"{parent}")


def _refuse_inputs_removed(path: Path, kind: str, old, present, keep: bool, inputs, name: str) -> None:
    """Refuse a run whose input lies among the outputs it would delete before it starts (an
    ``--initial R/final.npz`` with ``--overwrite --out R``)."""
    if keep or not inputs:
        return
    stale = set(present) | set(present_outputs(path, (old or {}).get("outputs", [])))
    here = path.resolve()
    for i in inputs:
        src = Path(i).resolve()
        for o in stale:
            if o != MANIFEST and _inside(src, here / o):
                raise RodwarpError(f"the input {i} lies in {path}, whose outputs this {kind} run deletes first "
                                   f"({o}); copy the input out of {path} first, or choose another {name}")


def _decide(path: Path, kind: str, parameters: dict, outputs, *, resume: bool, overwrite: bool, resumable: bool,
            replace_same_kind: bool, append: bool, legacy: dict | None, name: str, inputs=()):
    """What a run of ``kind`` may do with ``path``: raise the refusal, or return
    ``(old manifest or None, present outputs, run id to keep or None, keep outputs)``."""
    if kind not in OUTPUTS or any(not allowed_output(kind, o) for o in outputs):
        raise ValueError(f"outputs of a {kind} run must be bare names of OUTPUTS[{kind!r}]")  # a bug, not input
    output_location(path, name)
    _refuse_nested(path, kind, inputs, name)
    if resume and overwrite:
        raise RodwarpError(f"--resume and --overwrite contradict each other: --resume continues the run in "
                           f"{path}, --overwrite replaces it; pass one")
    old = _read_manifest(path) if path.is_dir() else None
    check_manifest(path, old, name)
    if old is None and legacy is not None:  # a run of this command from before manifests
        old = {"format": FORMAT, "kind": kind, "complete": True, "parameters": legacy, "legacy": True,
               "outputs": list(outputs)}
    if old is not None and _alive(old):
        raise RodwarpError(f"{path} is being written by a running {old.get('kind')} run (process {old.get('pid')} "
                           f"on this host); wait for it to finish, or choose another {name}")
    present = present_outputs(path, outputs)
    old_present = present_outputs(path, old.get("outputs", [])) if old is not None else []
    if old is not None and not old.get("complete") and not old.get("unreadable") and not old_present \
            and not (resume and old.get("kind") == kind) and not resumable:
        # a failed or killed start that wrote nothing: nothing of it to keep, so it does not
        # block the corrected command (its manifest is replaced below)
        old = None
    if resume:
        if old is None:
            if not resumable:
                raise RodwarpError(f"nothing to resume: {path} holds no unfinished {kind} run (no checkpoint); "
                                   "run the same command without --resume")
            return old, present, None, True
        if old.get("kind") != kind or old.get("unreadable"):
            raise RodwarpError(f"--resume continues only its own run: {path} holds {_describe(old)}; "
                               f"choose another {name}")
        if old.get("complete"):
            raise RodwarpError(f"nothing to resume: the {kind} run in {path} is finished; pass --overwrite to "
                               f"run it again, or another {name}")
        if not resumable:
            raise RodwarpError(f"nothing to resume: {path} holds {_describe(old)} that left no checkpoint; "
                               f"run the same command with --overwrite instead of --resume")
        diff = _param_diff(parameters, old.get("parameters", {}))
        if diff:
            was, now = old.get("parameters", {}), json.loads(json.dumps(parameters, default=str))
            shown = _differences(was, now, diff)
            raise RodwarpError(f"--resume continues only its own run: the run in {path} has other "
                               f"parameters ({shown}); repeat its original command with --resume, giving these "
                               f"as the run has them (a default may have changed since: CHANGELOG.md), or pass "
                               f"--overwrite to replace it")
        return old, present, old.get("run_id"), True
    if old is None and not present:
        return None, present, None, False
    same = old is not None and old.get("kind") == kind and not old.get("unreadable")
    marker = _TRAITS[kind]["legacy_marker"]
    if old is None and marker is not None:
        # a run of this command from before manifests: its marker, and nothing only another writes
        others = [o for k, t in _TRAITS.items() if k != kind for o in t["exclusive"]]
        same = marker in present and not any((path / o).exists() for o in others)
    if overwrite:
        return old, present, None, False
    if append and same:
        diff = _param_diff(parameters, old.get("parameters", {}))
        if diff:
            was, now = old.get("parameters", {}), json.loads(json.dumps(parameters, default=str))
            shown = _differences(was, now, diff)
            raise RodwarpError(f"{path} holds a {kind} of another protocol ({shown}); its results cannot be "
                               f"mixed with these: choose another {name}, or pass --overwrite to replace it")
        return old, present, old.get("run_id"), True
    if replace_same_kind and same:
        return old, present, None, False
    what = _describe(old) if old is not None else f"outputs of an earlier run ({', '.join(present[:4])})"
    hint = " --resume to continue it," if (old is not None and not old.get("complete") and resumable
                                           and old.get("kind") == kind and _TRAITS[kind]["resumable"]) else ""
    raise RodwarpError(f"{path} holds {what}; pass --overwrite to replace it,{hint} or choose another {name}")


def check(path, kind: str, parameters: dict, outputs, *, resume: bool = False, overwrite: bool = False,
          resumable: bool = False, replace_same_kind: bool = False, append: bool = False,
          legacy: dict | None = None, name: str = "--out", inputs=()) -> None:
    """Refuse, before any work, what :func:`claim` would refuse; changes nothing."""
    path = Path(path)
    old, present, _, keep = _decide(path, kind, parameters, outputs, resume=resume, overwrite=overwrite,
                                    resumable=resumable, replace_same_kind=replace_same_kind, append=append,
                                    legacy=legacy, name=name, inputs=inputs)
    _refuse_inputs_removed(path, kind, old, present, keep, inputs, name)


def claim(path, kind: str, parameters: dict, outputs, *, resume: bool = False, overwrite: bool = False,
          resumable: bool = False, replace_same_kind: bool = False, append: bool = False,
          legacy: dict | None = None, need_bytes: float = 0.0, name: str = "--out", inputs=()) -> RunDir:
    """Take the output folder ``path`` for a run, or refuse with one line saying why.

    Parameters
    ----------
    path : path-like
        The output folder (created).
    kind : str
        The command: a key of :data:`OUTPUTS`.
    parameters : dict
        Every parameter of the run (JSON-serialisable); compared on ``resume`` and ``append``.
    outputs : sequence of str
        Names of the files and folders the run writes in ``path`` (bare names or patterns of
        ``OUTPUTS[kind]``); with ``overwrite`` these (and those of the old manifest) are
        removed, never anything else.
    resume : bool
        Continue the folder's unfinished run of the same kind and parameters.
    overwrite : bool
        Replace whatever run the folder holds.
    resumable : bool
        The caller found something to resume (checkpoints).
    replace_same_kind : bool
        Replace an earlier run of the same kind without ``overwrite`` (analyses, segmentations).
    append : bool
        Continue the folder's run of the same kind and parameters, keeping its outputs
        (sweeps adding points); other parameters are refused, naming them.
    legacy : dict, optional
        Parameters of a run of this kind from before manifests that the caller found in the
        folder (a sweep's ``sweep.json``), compared as a manifest's would be.
    need_bytes : float
        Estimated disk space of the run (bytes), checked against the free space.
    name : str
        Option name used in messages.
    inputs : sequence of path-like
        The files and folders the run reads: refused when they lie among the outputs it
        deletes first; an analysis may lie in the run folder it analyses.

    Returns
    -------
    RunDir
    """
    path = Path(path)
    old, present, run_id, keep = _decide(path, kind, parameters, outputs, resume=resume, overwrite=overwrite,
                                         resumable=resumable, replace_same_kind=replace_same_kind, append=append,
                                         legacy=legacy, name=name, inputs=inputs)
    _refuse_inputs_removed(path, kind, old, present, keep, inputs, name)
    if need_bytes > 0:
        # outputs about to be replaced free their space
        need = need_bytes - (0 if keep else sum(_size(path / o) for o in present))
        disk_fits(path, need, f"this run's output ({name} {path})", "raise --save-every or free space")
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
    if run_id and not manifest["started"]:
        manifest["started"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    from rodwarp._version import __version__

    manifest["rodwarp"] = __version__
    run = RunDir(path, manifest)
    _CLAIMED[str(path.resolve())] = manifest["run_id"]
    # the folder is taken (new incomplete manifest) before the old outputs go, so a kill in
    # between leaves an incomplete run, never old outputs passing for the new run's
    run._write()
    if not keep:
        stale = set(present) | set(present_outputs(path, (old or {}).get("outputs", [])))
        for o in sorted(stale):
            if not allowed_output(kind, o) and not (old and allowed_output(old.get("kind"), o)):
                continue  # never reached (checked above); a deletion must be of a name we write
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
