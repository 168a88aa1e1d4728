"""Checks of every option before any work: finite, in range, consistent, and fitting.

Each check raises :class:`rodwarp.errors.RodwarpError` with one line that names the option,
says what is wrong and how to fix it. Size checks put their estimate in the message, so a
request that cannot fit in memory, on disk or in the box is refused in well under a second
instead of failing after minutes.
"""

from __future__ import annotations

import math
import os
import shutil
from pathlib import Path

from rodwarp.errors import RodwarpError

#: bytes of memory per simulated vertex (model, two states, contact lists, solver scratch and
#: the per-frame host copies): peak RSS of ``simulate`` went from 304 MB at 1k vertices to
#: 416 MB at 80k (1.4 kB per vertex); three times that covers contact-rich piles
BYTES_PER_VERTEX = 4_000
#: fixed memory of a run (Python, Warp, NumPy, matplotlib), bytes
BASE_BYTES = 300e6
#: bytes on disk per vertex per frame: trajectory.zarr (24 B, float64 xyz) plus the compressed
#: binary VTK frame (measured about 30 B per vertex on the main job, rounded up)
DISK_BYTES_PER_VERTEX_FRAME = 60
#: most steps a run may ask for (1e9 steps of the smallest scene take weeks on a CPU core)
MAX_STEPS = 1e9
#: densest random packing of long rods: phi * alpha ~ 5.4 (random contact equation); random
#: sequential addition stalls well below it, so more than this cannot be placed
MAX_PHI_ALPHA = 5.4


def fail(msg: str):
    raise RodwarpError(msg)


def _fmt(v) -> str:
    return f"{v:g}" if isinstance(v, float) else str(v)


def number(name: str, v, *, gt=None, ge=None, le=None, lt=None, unit: str = "", hint: str = "") -> float:
    """A finite number within the given bounds, else a one-line error naming ``--name``.

    Parameters
    ----------
    name : str
        Option name as the user typed it (``--alpha``).
    v : float
        The value.
    gt, ge, le, lt : float, optional
        Strict / inclusive lower and upper bounds.
    unit : str
        Unit shown after the bound (``s``, ``Hz``, ``m``).
    hint : str
        Extra advice appended to the message.
    """
    u = f" {unit}" if unit else ""
    rng = []
    if gt is not None:
        rng.append(f"> {_fmt(gt)}{u}")
    if ge is not None:
        rng.append(f">= {_fmt(ge)}{u}")
    if lt is not None:
        rng.append(f"< {_fmt(lt)}{u}")
    if le is not None:
        rng.append(f"<= {_fmt(le)}{u}")
    want = " and ".join(rng) if rng else "finite"
    if gt == 0 and ge is None and le is None and lt is None:
        want = f"positive (> 0{u})"
    try:
        f = float(v)
    except (TypeError, ValueError):
        fail(f"{name} must be a number ({want}), got {v!r}")
    tail = f"; {hint}" if hint else ""
    if not math.isfinite(f):
        fail(f"{name} must be a finite number, {want}, got {_fmt(f)}{tail}")
    if (gt is not None and not f > gt) or (ge is not None and not f >= ge) or (lt is not None and not f < lt) \
            or (le is not None and not f <= le):
        fail(f"{name} must be {want}, got {_fmt(f)}{tail}")
    return f


def integer(name: str, v, *, ge=None, le=None, hint: str = "") -> int:
    """An integer within bounds, else a one-line error naming ``--name``."""
    tail = f"; {hint}" if hint else ""
    if isinstance(v, bool) or not isinstance(v, (int,)) and not (isinstance(v, float) and v.is_integer()):
        fail(f"{name} must be a whole number, got {v!r}")
    i = int(v)
    if ge is not None and i < ge:
        fail(f"{name} must be >= {ge}, got {i}{tail}")
    if le is not None and i > le:
        fail(f"{name} must be <= {le}, got {i}{tail}")
    return i


def device_name(name: str, device: str) -> str:
    """``auto``, ``cpu``, ``cuda`` or ``cuda:N`` (availability is checked when the device is used)."""
    d = str(device).strip().lower()
    if d in ("auto", "cpu", "cuda") or (d.startswith("cuda:") and d[5:].isdigit()):
        return d
    fail(f"unknown device '{device}' for {name}; use auto, cpu, cuda or cuda:N")


def human_bytes(n: float) -> str:
    for unit in ("B", "kB", "MB", "GB", "TB", "PB"):
        if abs(n) < 1000 or unit == "PB":
            return f"{n:.3g} {unit}" if unit != "B" else f"{n:.0f} B"
        n /= 1000.0
    return f"{n:.3g} PB"  # pragma: no cover


def available_memory() -> float:
    """Memory this process may still use (bytes): MemAvailable, else physical memory."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return float(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return float(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - non-POSIX
        return float("inf")


def memory_fits(what: str, need: float, fix: str) -> None:
    """Refuse a request whose memory estimate ``need`` (bytes) exceeds what is available."""
    have = available_memory()
    if need > have:
        fail(f"{what} needs about {human_bytes(need)} of memory, {human_bytes(have)} is available; {fix}")


def existing_ancestor(path: Path) -> Path:
    """The path itself or its nearest existing parent."""
    p = Path(os.path.abspath(path))
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def disk_fits(path: Path, need: float, what: str, fix: str) -> None:
    """Refuse when the file system holding ``path`` has less than ``need`` bytes free."""
    base = existing_ancestor(path)
    if base.is_file():
        base = base.parent
    try:
        free = shutil.disk_usage(base).free
    except OSError:
        return
    if need > free:
        fail(f"{what} needs about {human_bytes(need)} on disk, {human_bytes(free)} is free at {base}; {fix}")


def probe_write(directory: Path) -> None:
    """Write and remove a 4 kB hidden file in ``directory`` (raises the OSError a real write gets)."""
    import tempfile

    fd, tmp = tempfile.mkstemp(prefix=".rodwarp-probe.", suffix=".tmp", dir=directory)
    try:
        os.write(fd, b"x" * 4096)
        os.fsync(fd)
    finally:
        os.close(fd)
        os.unlink(tmp)


def output_location(path, name: str = "--out", *, directory: bool = True) -> Path:
    """Check that ``path`` can be created and written, before any work.

    A directory output (``directory``) must not be an existing file and no parent may be a
    file; a file output must not be an existing directory. The nearest existing directory
    is probed with a real write (a temporary file, removed again), which catches read-only
    mounts and a full disk that permission bits do not show (root ignores them).

    Returns
    -------
    Path
        ``path``.
    """
    import errno

    path = Path(path)
    if directory and path.exists() and not path.is_dir():
        fail(f"{name} {path} is a file, not a directory; pass a directory path (it is created if missing)")
    if not directory and path.is_dir():
        fail(f"{name} {path} is a directory; pass a file path")
    p = Path(os.path.abspath(path if directory else path.parent))
    for parent in [p, *p.parents]:
        if parent.exists():
            if not parent.is_dir():
                fail(f"{name} {path}: {parent} is a file, so nothing can be created under it; choose another path")
            break
    probe_dir = existing_ancestor(p)
    try:
        probe_write(probe_dir)
    except OSError as e:
        why = {errno.EROFS: "the file system is read-only", errno.ENOSPC: "the disk is full",
               errno.EACCES: "permission denied", errno.EPERM: "permission denied",
               errno.EDQUOT: "the disk quota is exceeded"}.get(e.errno, e.strerror or str(e))
        fail(f"{name} {path}: cannot write in {probe_dir} ({why}); choose a writable location")
    return path


# ------------------------------------------------------------------------------ simulate

#: deepest overlap of two input rods that the contact solver pushes apart without a blow-up
#: (the engine stops a run at a quarter diameter; the main job's own packings stay below 0.1 d)
MAX_INPUT_OVERLAP = 0.1
#: options that mean nothing with --initial (the input decides them)
NOT_WITH_INITIAL = ("n_rods", "vertices", "box", "seed")


def stage_steps(duration: float, dt: float) -> int:
    """Steps of a stage of ``duration`` s at step ``dt`` s, as the protocol counts them."""
    return int(round(duration / dt))


def check_protocol(p) -> None:
    """Every check of :class:`rodwarp.protocol.ProtocolParams`, in the order the options are
    listed by ``rodwarp simulate --help``; the input rod set (``initial``) is loaded and
    checked too (see :func:`check_input_rods`).

    Parameters
    ----------
    p : rodwarp.protocol.ProtocolParams
        The parameters; ``p._explicit`` (a set of field names, optional) lists the options the
        user typed, so that options --initial decides can be refused when given.
    """
    explicit = set(getattr(p, "_explicit", ()) or ())
    number("--alpha", p.alpha, gt=1, hint="alpha is rod length over diameter")
    for name in ("freq", "entangle_freq"):
        number(f"--{name.replace('_', '-')}", getattr(p, name), ge=0, unit="Hz")
    for name in ("amplitude", "entangle_amplitude"):
        number(f"--{name.replace('_', '-')}", getattr(p, name), ge=0, unit="m")
    number("--gravity", p.gravity, gt=0, unit="m/s^2")
    number("--duration", p.duration, gt=0, unit="s", hint="the stability test needs at least one step")
    number("--entangle-duration", p.entangle_duration, ge=0, unit="s", hint="0 skips entangling")
    number("--static-load", p.static_load, ge=0, hint="in units of a rod's weight")
    if p.n_rods is not None:
        integer("--n-rods", p.n_rods, ge=1)
    number("--length", p.length, gt=0, unit="m")
    integer("--vertices", p.vertices, ge=2, le=10_000)
    box = tuple(p.box)
    if len(box) != 3:
        fail(f"--box must be three positive numbers 'X,Y,Z' in rod lengths, got {box}")
    for axis, v in zip("XYZ", box):
        number(f"--box {axis}", v, gt=0, hint="the box is 'X,Y,Z' in rod lengths")
    number("--mu", p.mu, ge=0)
    number("--young", p.young, gt=0, unit="Pa")
    number("--density", p.density, gt=0, unit="kg/m^3")
    if p.dt is not None:
        number("--dt", p.dt, gt=0, unit="s", hint="leave it out for the default step")
    integer("--iterations", p.iterations, ge=1, le=100_000)
    number("--step-safety", p.step_safety, gt=0, le=4, hint="the fraction of a diameter the fastest rod may cross per step")
    if p.rod_model not in ("auto", "rigid", "elastic"):
        fail(f"--rod-model must be auto, rigid or elastic, got '{p.rod_model}'")
    number("--save-every", p.save_every, gt=0, unit="s")
    number("--checkpoint-every", p.checkpoint_every, gt=0, unit="s")
    integer("--seed", p.seed, ge=0, le=2**63 - 1)
    device_name("--device", p.device)
    if p.entangle and not p.initial:
        fail("--entangle only applies with --initial (a random packing is always entangled first); drop it")
    if p.initial:
        given = sorted(k for k in NOT_WITH_INITIAL if k in explicit or (k == "n_rods" and p.n_rods is not None))
        if given:
            opts = ", ".join(f"--{k.replace('_', '-')}" for k in given)
            fail(f"{opts} do{'es' if len(given) == 1 else ''} not apply with --initial (the input rod set "
                 f"decides {'it' if len(given) == 1 else 'them'}); drop {opts}")

    # consistency of durations, intervals and the step
    stages = [("stability test", "--duration", p.duration)]
    if p.entangle_duration > 0 and (not p.initial or p.entangle):
        stages.insert(0, ("entangling", "--entangle-duration", p.entangle_duration))
    if p.save_every > p.duration:
        fail(f"--save-every {p.save_every:g} s is longer than the stability test (--duration {p.duration:g} s): "
             f"the verdict needs samples inside the test; lower --save-every")
    if p.dt is not None:
        for title, opt, dur in stages:
            if p.dt > dur or stage_steps(dur, p.dt) < 1:
                fail(f"--dt {p.dt:g} s is longer than the {title} ({opt} {dur:g} s): not a single full step fits; "
                     f"lower --dt below {dur:g} s or leave it out for the default step")
        check_step_count(p, p.dt, "--dt")
    # the step can never exceed 1/40 of a drive period (solver default): a lower bound on the work
    for title, opt, dur in stages:
        f = p.entangle_freq if title == "entangling" else p.freq
        if f > 0 and 40.0 * f * dur > MAX_STEPS:
            fq = "--entangle-freq" if title == "entangling" else "--freq"
            fail(f"{fq} {f:g} Hz over {opt} {dur:g} s needs at least {40.0 * f * dur:.3g} steps (40 per period), "
                 f"more than {MAX_STEPS:.0e}; lower the frequency or the duration")
    height = box[2] * p.length
    if 2 * p.entangle_amplitude >= 0.5 * height or 2 * p.amplitude >= 0.5 * height:
        fail(f"vibration amplitude does not fit the box (height {height:g} m); lower --amplitude")

    if p.initial:
        rods = check_input_rods(p, explicit)
        n_vertices = rods.n_vertices
    else:
        n = p.rods
        d = p.length / p.alpha
        diag = math.sqrt(sum(v * v for v in box))
        if diag < 1.0 + 1.0 / p.alpha:
            fail(f"--box {','.join(f'{v:g}' for v in box)} (rod lengths) is too small to hold one rod "
                 f"(diagonal {diag:.3g} < 1 + d/l); enlarge --box")
        n_vertices = n * int(p.vertices)
        memory_fits(f"{n} rods x {p.vertices} vertices", BASE_BYTES + BYTES_PER_VERTEX * n_vertices,
                    "lower --n-rods (default round(5.4 alpha)), --alpha or --vertices")
        vol = float(box[0] * box[1] * box[2]) * p.length**3
        phi = n * math.pi * d * d * p.length / 4.0 / vol
        if phi * p.alpha > MAX_PHI_ALPHA:
            fail(f"{n} rods of aspect ratio {p.alpha:g} would fill {phi:.3g} of the box (phi * alpha = "
                 f"{phi * p.alpha:.3g}); random packing places at most phi * alpha ~ {MAX_PHI_ALPHA:g}: "
                 f"lower --n-rods or enlarge --box")
    p._n_vertices = n_vertices
    frames = 1 + sum(int(math.ceil(dur / p.save_every)) + 1 for _, _, dur in stages)
    p._frames = frames


def check_step_count(p, dt: float, source: str) -> None:
    """Refuse a run of more than :data:`MAX_STEPS` steps at step ``dt`` (s)."""
    stages = [p.duration]
    if p.entangle_duration > 0 and (not p.initial or p.entangle):
        stages.append(p.entangle_duration)
    steps = sum(stage_steps(d, dt) for d in stages)
    if steps > MAX_STEPS:
        fail(f"the run needs {steps:.3g} steps at dt = {dt:.3g} s ({source}), more than {MAX_STEPS:.0e} "
             f"(weeks of computing); shorten --duration/--entangle-duration or lower --alpha")


#: bytes per vertex of the two checkpoints kept (state, warm-start impulses; the main job's
#: are 170 B per vertex each) and of initial.npz + final.npz, rounded up
DISK_BYTES_PER_VERTEX_FIXED = 2 * 400 + 2 * 100
#: the three PNG figures and the small files of a run
DISK_BYTES_FIXED = 1.0e6


def output_bytes(p) -> float:
    """Disk space a run needs (bytes): its frames (trajectory plus VTK, every --save-every),
    checkpoints, rod sets and figures."""
    V = float(getattr(p, "_n_vertices", 0))
    return float(getattr(p, "_frames", 0)) * V * DISK_BYTES_PER_VERTEX_FRAME + V * DISK_BYTES_PER_VERTEX_FIXED \
        + DISK_BYTES_FIXED


def check_input_rods(p, explicit=()):
    """Load and check the --initial rod set; set ``p.alpha`` and ``p.length`` from it.

    Refuses an empty set, non-metric units, rods overlapping deeper than
    :data:`MAX_INPUT_OVERLAP` diameters (naming the deepest pair), an --alpha or --length
    that contradicts the input, and a set too large for memory. The rods (in metres) are kept
    on ``p`` for the run.

    Returns
    -------
    RodSet
        The input rods in metres.
    """
    import numpy as np

    from rodwarp.rodset import detect_contacts
    from rodwarp.rodset import UNITS, load

    path = Path(p.initial)
    if not path.exists():
        fail(f"initial rod set not found: {path}; check the --initial path")
    cached = getattr(p, "_input_rods", None)
    if cached is not None and getattr(p, "_input_key", None) == (str(path), p.alpha, p.length):
        return cached
    rods = load(path, diameter=p.length / p.alpha)
    if rods.n_rods == 0:
        fail(f"--initial {path} holds no rods; nothing to simulate")
    if rods.units not in UNITS or rods.units == "voxel":
        fail(f"--initial {path} is in '{rods.units}' units; convert it to metres first "
             f"(RodSet.to_units('m', voxel_size=...))")
    if rods.units != "m":
        rods = rods.to_units("m")
    memory_fits(f"--initial {path} ({rods.n_rods} rods, {rods.n_vertices} vertices)",
                BASE_BYTES + BYTES_PER_VERTEX * rods.n_vertices, "simulate a smaller rod set")
    d = float(np.mean(rods.diameters))
    lengths = rods.rod_lengths()
    if not np.all(lengths > 0):
        k = int(np.flatnonzero(~(lengths > 0))[0])
        fail(f"--initial {path}: rod {k} has zero length; remove it")
    length = float(np.mean(lengths))
    alpha = length / d
    if "alpha" in explicit and not math.isclose(p.alpha, alpha, rel_tol=0.01):
        fail(f"--alpha {p.alpha:g} contradicts the input rods (l / d = {length:.4g} / {d:.4g} = {alpha:.4g} "
             f"from {path}); drop --alpha")
    if "length" in explicit and not math.isclose(p.length, length, rel_tol=0.01):
        fail(f"--length {p.length:g} m contradicts the input rods (mean length {length:.4g} m in {path}); "
             f"drop --length")
    c = detect_contacts(rods, tolerance=-MAX_INPUT_OVERLAP * d)
    if len(c):
        k = int(np.argmin(c.gap))
        i, j = int(c.rod_i[k]), int(c.rod_j[k])
        depth = -float(c.gap[k]) / d
        more = f" ({len(c)} pairs overlap by more than {MAX_INPUT_OVERLAP:g} d)" if len(c) > 1 else ""
        fail(f"--initial {path}: rods {i} and {j} overlap by {depth:.2g} d{more}; separate them "
             f"(the contact solver pushes apart at most {MAX_INPUT_OVERLAP:g} d without blowing up)")
    p.alpha = alpha
    p.length = length
    p._input_rods = rods
    p._input_key = (str(path), p.alpha, p.length)
    return rods


# ------------------------------------------------------------------------------ analyze, CT

#: bytes per voxel of `rodwarp analyze` (seven float64 fields, the valid mask, labels and the
#: batch scratch of the kernels), rounded up
ANALYZE_BYTES_PER_VOXEL = 200
#: bytes per voxel of `rodwarp phantom`: the float64 occupancy, the blurred copy, the noise and
#: the 16-bit output
PHANTOM_BYTES_PER_VOXEL = 34


def check_analyze(o) -> None:
    """Checks of :class:`rodwarp.analyze.AnalyzeOptions` (lengths in the input's units)."""
    from rodwarp.rodset import UNITS

    for name in ("radius", "spacing", "diameter", "length"):
        val = getattr(o, name)
        if val is not None:
            number(f"--{name}", val, gt=0, hint="lengths are in the input's units")
    if o.contact_tolerance is not None:
        number("--contact-tolerance", o.contact_tolerance, ge=0, hint="a surface gap in the input's units")
    if o.units is not None and o.units not in UNITS:
        fail(f"--units must be one of {', '.join(UNITS)}, got '{o.units}'")
    if o.outlier not in ("q3", "q1"):
        fail(f"--outlier must be q3 (Q3 + 1.5 IQR, the paper's) or q1, got '{o.outlier}'")
    if o.connectivity not in (6, 26):
        fail(f"--connectivity must be 6 or 26, got {o.connectivity}")
    integer("--bins", o.bins, ge=2, le=100_000)
    device_name("--device", o.device)


def check_grid_memory(n_voxels: float) -> None:
    """Refuse an analysis grid whose memory estimate exceeds what is available."""
    memory_fits(f"the analysis grid ({n_voxels:.3g} voxels)", BASE_BYTES + ANALYZE_BYTES_PER_VOXEL * n_voxels,
                "raise --spacing or --radius")


PHANTOM_SCENES = ("random", "bundles", "arcs", "wires")


def check_phantom(*, rods, shape, voxel_size, out, blur, cnr, ring, cupping, streaks, n_rods, radius, aspect,
                  touching, seed, fov=None, z_thickness=1) -> None:
    """Checks of ``rodwarp phantom``: values, the volume's memory and disk size, the output path."""
    if len(shape) != 3:
        fail(f"--shape must be three sizes Z Y X, got {shape}")
    for axis, n in zip("ZYX", shape):
        integer(f"--shape {axis}", n, ge=2, hint="three sizes >= 2 (Z Y X)")
    number("--voxel-size", voxel_size, gt=0)
    number("--blur", blur, ge=0, unit="voxels")
    number("--cnr", cnr, gt=0)
    number("--ring", ring, ge=0)
    number("--cupping", cupping, gt=-1, lt=1, hint="a relative intensity drop (negative: a bright rim)")
    if fov is not None:
        number("--fov", fov, gt=0, unit="voxels")
    integer("--z-thickness", z_thickness, ge=1, le=100)
    number("--streaks", streaks, ge=0)
    integer("--seed", seed, ge=0, le=2**63 - 1)
    if rods in PHANTOM_SCENES:
        integer("--n-rods", n_rods, ge=1, le=10_000_000)
        number("--radius", radius, gt=0, unit="voxels")
        if rods == "random":
            number("--aspect", aspect, gt=1)
            number("--touching", touching, ge=0, le=1)
            length = 2 * radius * aspect
            if length > max(shape):
                fail(f"'random' rods of --radius {radius:g} and --aspect {aspect:g} are {length:g} voxels long, "
                     f"longer than the volume ({max(shape)} voxels); lower --aspect or --radius, or enlarge --shape")
    elif not Path(rods).exists():
        fail(f"rod set '{rods}' does not exist; pass a rod-set file, a simulate output folder or a scene "
             f"({', '.join(PHANTOM_SCENES)})")
    n_vox = float(shape[0]) * float(shape[1]) * float(shape[2]) * float(z_thickness)
    memory_fits(f"--shape {' '.join(str(s) for s in shape)} ({n_vox:.3g} voxels)",
                BASE_BYTES + PHANTOM_BYTES_PER_VOXEL * n_vox, "lower --shape")
    out = Path(out)
    if out.suffix.lower() not in (".tif", ".tiff"):
        fail(f"--out {out} must end in .tif or .tiff (a multi-page TIFF)")
    output_location(out, "--out", directory=False)
    disk_fits(out, 2.0 * n_vox, f"the 16-bit TIFF of --shape {' '.join(str(s) for s in shape)}", "lower --shape")


def check_segment(*, stack, voxel_size, units, diameter, out, chunk, contact_tolerance, min_fill=0.6) -> None:
    """Checks of ``rodwarp segment`` before the volume is read (``voxel_size``: None for the
    file's metadata, or one or three comma-separated values z,y,x)."""
    from rodwarp.rodset import UNITS

    if not Path(stack).exists():
        fail(f"CT stack '{stack}' does not exist; pass a multi-page TIFF, a folder of slices or a zarr array")
    if voxel_size is not None:
        parts = [p for p in str(voxel_size).split(",") if p.strip()]
        if len(parts) not in (1, 3):
            fail(f"--voxel-size takes one value or three (z,y,x), got '{voxel_size}'")
        for p in parts:
            try:
                val = float(p)
            except ValueError:
                fail(f"--voxel-size must be numbers, got '{voxel_size}'")
            number("--voxel-size", val, gt=0, hint=f"in --units {units or 'mm'}")
    if units is not None and units not in UNITS:
        fail(f"--units must be one of {', '.join(UNITS)}, got '{units}'")
    number("--min-fill", min_fill, gt=0, le=1)
    if diameter is not None:
        number("--diameter", diameter, gt=0, hint=f"in --units {units}")
    if chunk is not None:
        integer("--chunk", chunk, ge=16, hint="an edge of at least 16 voxels")
    number("--contact-tolerance", contact_tolerance, ge=0, unit="voxels")
    output_location(Path(out), "--out")


# ------------------------------------------------------------------------------ sweep

def check_scheduler(address: str, timeout: float = 3.0) -> str:
    """A Dask scheduler address that is well formed and answers a TCP connection, else a
    one-line error within ``timeout`` seconds.

    Returns
    -------
    str
        The address with a ``tcp://`` scheme added when it had none.
    """
    import re
    import socket

    a = address.strip()
    if "://" not in a:
        a = "tcp://" + a
    m = re.fullmatch(r"(tcp|tls)://(\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.\-]+):(\d{1,5})", a)
    if not m:
        fail(f"--scheduler '{address}' is not a Dask scheduler address; use tcp://HOST:PORT "
             f"(e.g. tcp://head-node:8786), or leave it out for a local cluster")
    host, port = m.group(2).strip("[]"), int(m.group(3))
    if not 0 < port < 65536:
        fail(f"--scheduler '{address}': port {port} is out of range 1-65535")
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except socket.gaierror:
        fail(f"--scheduler '{address}': unknown host '{host}'; check the address")
    except OSError as e:
        why = "timed out" if isinstance(e, TimeoutError) or "timed out" in str(e) else (e.strerror or str(e))
        fail(f"--scheduler '{address}' does not answer ({why.lower()}; waited at most {timeout:g} s); "
             f"start it with `dask scheduler` on that host or check the address")
    return a
