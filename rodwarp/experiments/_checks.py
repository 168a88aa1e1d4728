"""Checks of ``rodwarp simulate`` and ``rodwarp sweep`` before any work.

:func:`check_protocol` is :meth:`ProtocolParams.validate`: every option finite, in range and
consistent (a run has at least one step, ``--save-every`` fits in the test, ``--dt`` in every
stage), the run's memory, disk and box estimates checked, and an ``--initial`` rod set loaded
and checked. The generic checks come from :mod:`rodwarp.validation`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path

from rodwarp.experiments._plan import frames
from rodwarp.experiments.protocols import plan
from rodwarp.validation import BASE_BYTES, check_ranges, device_name, fail, memory_fits, number

#: bytes of memory per simulated vertex (model, two states, contact lists, solver scratch and
#: the per-frame host copies): peak RSS of ``simulate`` went from 304 MB at 1k vertices to
#: 416 MB at 80k (1.4 kB per vertex); three times that covers contact-rich piles
BYTES_PER_VERTEX = 4_000
#: bytes on disk per vertex per frame: trajectory.zarr (24 B, float64 xyz) plus the compressed
#: binary VTK frame (measured about 30 B per vertex on the main job, rounded up)
DISK_BYTES_PER_VERTEX_FRAME = 60
#: most steps a run may ask for (1e9 steps of the smallest scene take weeks on a CPU core)
MAX_STEPS = 1e9
#: densest random packing of long rods: phi * alpha ~ 5.4 (random contact equation); random
#: sequential addition stalls well below it, so more than this cannot be placed
MAX_PHI_ALPHA = 5.4
#: deepest overlap of two input rods that the contact solver pushes apart without a blow-up
#: (the engine stops a run at a quarter diameter; the main job's own packings stay below 0.1 d)
MAX_INPUT_OVERLAP = 0.1
#: shortest checkpoint interval (s of simulated time) unless --save-every is shorter still: a
#: checkpoint is taken at most once per step, so a shorter interval checkpoints every step (2.6x
#: slower, measured) while sparing a resume less than a hundredth of a second of simulation,
#: a tenth of the 10 Hz drive's period
CHECKPOINT_FLOOR = 0.01
#: options that mean nothing with --initial (the input decides them)
NOT_WITH_INITIAL = ("n_rods", "vertices", "box", "seed")


#: the strongest drive accepted, peak acceleration over gravity: the paper's entangling drive is
#: a/g ~ 400 at its rescaled gravity (5 cm at 10 Hz, g 0.5), its tests 0.3 to 7.9; beyond 1000 a
#: drive is a typo or a shock, and it tears any packing apart
MAX_A_OVER_G = 1000.0
#: the widest plate stroke of a poured packing, in rod lengths: the alpha* study's largest drive
#: is l / 2; a plate swinging more than two rod lengths throws rods out of any container
MAX_PLATE_AMPLITUDE_LENGTHS = 2.0
#: the IMC stiffness accepted, in heaviest-rod weights per delta: the default is 1000 and DisMech's
#: floor about 100; below 1 a rod's own weight pushes it through delta, above 1e6 the penalty is a
#: rigid wall (a 20-weight contact overlaps 2e-5 delta), outside the range docs/physics.md checks
#: its implicit solve in; the exact law is the rigid one
IMC_STIFFNESS_WEIGHTS_RANGE = (1.0, 1e6)


def stage_steps(duration: float, dt: float) -> int:
    """Steps of a stage of ``duration`` s at step ``dt`` s, as the protocol counts them."""
    return int(round(duration / dt))


@dataclass(frozen=True)
class CheckedProtocol:
    """Parameters that passed :func:`check_protocol`, with what the check found.

    Attributes
    ----------
    params : rodwarp.experiments.ProtocolParams
        The parameters the run uses: with an ``initial`` rod set, ``alpha`` and ``length``
        are the input's (l / d and the mean rod length, m).
    input_rods : RodSet or None
        The ``initial`` rod set, loaded, checked and in metres; None for a random packing.
    n_vertices : int
        Vertices the run simulates (sizes its memory and disk estimates).
    frames : int
        Frames the run records (one every ``save_every``).
    """

    params: object
    input_rods: object
    n_vertices: int
    frames: int


def check_protocol(p, explicit=None) -> CheckedProtocol:
    """Every check of :class:`rodwarp.experiments.ProtocolParams`, in the order the options are
    listed by ``rodwarp simulate --help``; the input rod set (``initial``) is loaded and
    checked too (see :func:`check_input_rods`), and the options are checked again with its
    aspect ratio and length.

    Parameters
    ----------
    p : rodwarp.experiments.ProtocolParams
        The parameters (not changed: they are frozen).
    explicit : iterable of str or None
        Field names of the options the user typed, so that options --initial decides can be
        refused when given, and an --alpha or --length that contradicts the input too; a
        protocol with defaults of its own (excitation) takes them for every option not in it.
        None: the fields that differ from ProtocolParams' defaults.

    Returns
    -------
    CheckedProtocol
        The parameters the run uses and what the check loaded and counted.
    """
    from rodwarp.experiments.protocols import protocol

    # the protocol's own defaults for what was not given (an API caller: what differs from
    # ProtocolParams' defaults)
    duration_given = ("duration" in explicit) if explicit is not None else _changed(p, ["duration"])
    p = protocol(p.protocol).resolve(p, None if explicit is None else explicit)
    p = resolve_cycles(p, duration_given)
    explicit = frozenset(explicit or ())
    stages = _check_options(p, explicit)
    rods = None
    if p.initial:
        rods, alpha, length = check_input_rods(p, explicit)
        p = replace(p, alpha=alpha, length=length)
        stages = _check_options(p, explicit)  # durations, steps and the box against the input's l
        n_vertices = rods.n_vertices
    else:
        n_vertices = _check_packing(p)
    return CheckedProtocol(p, rods, n_vertices, frames(stages, p.save_every))


def resolve_cycles(p, duration_given: bool):
    """``p`` with the stability test's duration set from ``cycles`` (cycles / freq, s), refused
    (one line) when ``--duration`` was given too and disagrees, or the test has no frequency."""
    if p.cycles is None:
        return p
    for name in ("cycles", "freq"):  # their own ranges first: the duration is derived from them
        type(p).__dataclass_fields__[name].metadata["range"].check(f"--{name}", getattr(p, name))
    if not p.freq > 0:
        fail(f"--cycles {p.cycles:g} counts drive periods, but --freq is {p.freq:g} Hz; give --freq > 0 or set "
             "the test's length with --duration")
    duration = p.cycles / p.freq
    if duration_given and not math.isclose(p.duration, duration, rel_tol=1e-9):
        fail(f"--cycles {p.cycles:g} and --duration {p.duration:g} both set the stability test's length "
             f"({p.cycles:g} cycles at {p.freq:g} Hz is {duration:.6g} s); give one of them")
    return replace(p, duration=duration)


def _check_options(p, explicit: frozenset):
    """The checks of every option and of their consistency; returns the plan's stages."""
    from rodwarp.experiments.protocols import protocol

    proto = protocol(p.protocol)
    # every field within the range stated beside it (ProtocolParams); then what ties them together
    check_ranges(p)
    poured = proto.poured  # rods poured into an open container, not placed in a closed box
    if not poured and p.duration == 0:
        fail("--duration 0 leaves the stability test without a step (0 leaves out the shaking of --protocol lab or "
             "excitation only); give --duration > 0 s")
    if len(tuple(p.box)) != 3:
        fail(f"--box must be three positive numbers 'X,Y,Z' in rod lengths, got {tuple(p.box)}")
    box = tuple(p.box)
    if p.rod_model not in ("auto", "rigid", "elastic"):
        fail(f"--rod-model must be auto, rigid or elastic, got '{p.rod_model}'")
    if p.contact_law is not None and p.contact_law not in ("exact", "imc"):
        fail(f"--contact-law must be exact or imc, got '{p.contact_law}'")
    if p.contact_law != "imc":
        for name in ("imc_delta", "imc_nu", "imc_stiffness"):
            if getattr(p, name) is not None:
                fail(f"--{name.replace('_', '-')} only applies with --contact-law imc; add it or drop the option")
    if p.contact_law == "imc" and p.restitution:
        fail(f"--restitution {p.restitution:g} only applies with the exact contact law (IMC's penalty has its own "
             "rebound); drop it or use --contact-law exact")
    if ("fill_height" in proto.fields and p.n_rods is not None
            and ("fill_height" in explicit or _changed(p, ["fill_height"]))):
        fail(f"--fill-height and --n-rods both set the lab protocol's rod count (--fill-height {p.fill_height:g} "
             f"rod lengths is {proto.rods(p)} rods, --n-rods {p.n_rods}); give one of them")
    _check_drives(p)
    if p.imc_stiffness is not None:
        _check_imc_stiffness(p)
    floor = min(CHECKPOINT_FLOOR, p.save_every)
    if p.checkpoint_every < floor:
        fail(f"--checkpoint-every {p.checkpoint_every:g} s is below {floor:g} s of simulated time: it writes a "
             f"checkpoint after nearly every step (a run checkpointing every step is about 2.6 times slower) "
             f"while a resume would save under {floor:g} s; use --checkpoint-every {floor:g} or more (default 1)")
    if p.fields_every > 0:
        k = p.fields_every / p.save_every
        if k < 1 - 1e-9 or abs(k - round(k)) > 1e-6 * max(k, 1.0):
            fail(f"--fields-every {p.fields_every:g} s must be a whole multiple of --save-every {p.save_every:g} s "
                 f"(the fields are taken at sample times); e.g. --fields-every {max(1, round(k)) * p.save_every:g}")
    device_name("--device", p.device)
    if p.entangle and not p.initial:
        fail("--entangle only applies with --initial (a random packing is always entangled first); drop it")
    if p.entangle and p.entangle_duration == 0:
        fail("--entangle asks for the entangling stage but --entangle-duration 0 skips it; give "
             "--entangle-duration > 0 or drop --entangle")
    for name, opt in (("units", "--units"), ("initial_diameter", "--diameter")):
        if getattr(p, name, None) is not None and not p.initial:
            fail(f"{opt} only applies with --initial (it describes the input rod set; a random packing is in "
                 f"metres with d = --length / --alpha); drop it")
    if p.initial:
        given = sorted(k for k in NOT_WITH_INITIAL if k in explicit or (k == "n_rods" and p.n_rods is not None))
        if given:
            opts = ", ".join(f"--{k.replace('_', '-')}" for k in given)
            fail(f"{opts} do{'es' if len(given) == 1 else ''} not apply with --initial (the input rod set "
                 f"decides {'it' if len(given) == 1 else 'them'}); drop {opts}")

    _check_protocol_fields(p)
    proto.check(p)

    # consistency of durations, intervals and the step
    stages = plan(p)
    test = next(s for s in stages if s.test)
    if test.interval(p.save_every) > test.duration:
        fail(f"--save-every {p.save_every:g} s is longer than the {test.title} ({test.option} {test.duration:g} s): "
             f"the verdict needs samples inside the test; lower --save-every")
    if p.samples_per_cycle and not test.freq > 0:
        fail(f"--samples-per-cycle {p.samples_per_cycle} samples the {test.title} per drive period, but its drive "
             "has no frequency; drop it (the test samples every --save-every)")
    if p.dt is not None:
        for s in stages:
            if p.dt > s.duration or stage_steps(s.duration, p.dt) < 1:
                fail(f"--dt {p.dt:g} s is longer than the {s.title} ({s.option} {s.duration:g} s): not a single full "
                     f"step fits; lower --dt below {s.duration:g} s or leave it out for the default step")
        check_step_count(p, p.dt, "--dt")
    # the step can never exceed 1/(steps per period) of a drive period: a lower bound on the work
    for s in stages:
        if s.min_steps(p.steps_per_period) > MAX_STEPS:
            fq = s.option.replace("duration", "freq")
            fail(f"{fq} {s.freq:g} Hz over {s.option} {s.duration:g} s needs at least {s.min_steps(p.steps_per_period):.3g} "
                 f"steps ({p.steps_per_period:g} per period), more than {MAX_STEPS:.0e}; lower the frequency or the duration")
    height = box[2] * p.length
    box_drives = {"--amplitude": p.amplitude} if not poured else {}
    for st in stages if not poured else ():
        if st.amplitude > 0 and st.option:
            box_drives.setdefault(_drive_options(st)[1], st.amplitude)
    for opt, a in box_drives.items():
        if 2 * a >= 0.5 * height:
            fail(f"{opt} {a:g} m (a stroke of {2 * a:g} m) does not fit the box: its height is {height:g} m ({box[2]:g} "
                 f"rod lengths of --length {p.length:g} m) and a stroke may take at most half of it; lower {opt}, "
                 f"or raise --length or the box's Z")
    return stages


def _drive_options(stage) -> tuple[str, str]:
    """The options that set a stage's drive, from the option of its duration
    (``--entangle-duration``: ``--entangle-freq``, ``--entangle-amplitude``)."""
    return stage.option.replace("duration", "freq"), stage.option.replace("duration", "amplitude")


def _check_drives(p) -> None:
    """Each drive's strength (a/g) and stroke against what the scene can take."""
    from rodwarp.experiments.protocols import protocol

    poured = protocol(p.protocol).poured
    # the test's drive always, and every other stage's drive of the plan (the paper's entangling)
    drives = {("--freq", "--amplitude"): (p.freq, p.amplitude)}
    for st in plan(p):
        if st.amplitude > 0 and st.option:
            drives.setdefault(_drive_options(st), (st.freq, st.amplitude))
    for (fopt, aopt), (f, a) in drives.items():
        a_g = 4 * math.pi**2 * f * f * a / p.gravity
        if a_g > MAX_A_OVER_G:
            fail(f"{fopt} {f:g} Hz and {aopt} {a:g} m make a/g = {a_g:.3g} at --gravity {p.gravity:g} m/s^2, above "
                 f"{MAX_A_OVER_G:g}: a drive that tears any packing apart (the paper's entangling drive is a/g ~ 400, "
                 f"its tests 0.3 to 7.9); lower {aopt} or {fopt}")
    if poured and p.amplitude > MAX_PLATE_AMPLITUDE_LENGTHS * p.length:
        fail(f"--amplitude {p.amplitude:g} m is more than {MAX_PLATE_AMPLITUDE_LENGTHS:g} rod lengths (l = "
             f"{p.length:g} m): the plate would throw the rods out of any container (the paper's strokes are 1 to "
             f"25 mm); lower --amplitude")


def _check_imc_stiffness(p) -> None:
    """The IMC stiffness in the unit that makes sense of it: heaviest-rod weights per delta."""
    from rodwarp.sim.contact_law import IMC_DELTA_DIAMETERS

    d = p.diameter
    weight = p.density * p.effective_gravity * math.pi / 4 * d * d * p.length
    delta = (p.imc_delta if p.imc_delta is not None else IMC_DELTA_DIAMETERS) * d
    ratio = p.imc_stiffness * delta / weight
    lo, hi = IMC_STIFFNESS_WEIGHTS_RANGE
    if not lo <= ratio <= hi:
        fail(f"--imc-stiffness {p.imc_stiffness:g} N/m is {ratio:.3g} rod weights per delta ({weight:.3g} N per "
             f"{delta:.3g} m), outside {lo:g} to {hi:g}: " + ("a rod's own weight would push it through delta"
                                                            if ratio < lo else "the penalty is then a rigid wall, "
                                                            "outside the range its implicit solve was checked in; "
                                                            "--contact-law exact is the rigid law") +
             f"; use {1000 * weight / delta:.3g} N/m (1000 rod weights per delta, the default) or leave it out")


def _check_protocol_fields(p) -> None:
    """Refuse, in one line, options of another protocol than ``p.protocol`` (each protocol's
    ``fields``, :data:`rodwarp.experiments.protocols.PROTOCOLS`)."""
    from rodwarp.experiments.protocols import PROTOCOLS

    mine = set(PROTOCOLS[p.protocol].fields)
    others = [k for name, proto in PROTOCOLS.items() if name != p.protocol for k in proto.fields if k not in mine]
    given = _changed(p, dict.fromkeys(others))
    if not given:
        return
    opts = ", ".join(f"--{k.replace('_', '-')}" for k in given)
    owners = sorted({name for name, proto in PROTOCOLS.items() for k in given if k in proto.fields})
    fail(f"{opts} do{'es' if len(given) == 1 else ''} not apply with --protocol {p.protocol} (only with "
         f"--protocol {' or '.join(owners)}); drop {opts}")


def _changed(p, names) -> list[str]:
    from dataclasses import fields

    defaults = {f.name: f.default for f in fields(p)}
    return [n for n in names if getattr(p, n) != defaults[n] and not (n == "box" and list(p.box) == list(defaults[n]))]


def _check_packing(p) -> int:
    """The random packing's checks (the box holds a rod, memory, density); its vertex count."""
    box = tuple(p.box)
    n = p.rods
    from rodwarp.experiments.protocols import protocol

    if protocol(p.protocol).poured:  # the pour column is dilute by construction (ProtocolParams.pour_height)
        n_vertices = n * p.n_vertices
        memory_fits(f"{n} rods x {p.n_vertices} vertices", BASE_BYTES + BYTES_PER_VERTEX * n_vertices,
                    "lower --n-rods, --fill-height, --container-radius or --vertices")
        return n_vertices
    d = p.length / p.alpha
    diag = math.sqrt(sum(v * v for v in box))
    if diag < 1.0 + 1.0 / p.alpha:
        fail(f"--box {','.join(f'{v:g}' for v in box)} (rod lengths) is too small to hold one rod "
             f"(diagonal {diag:.3g} < 1 + d/l); enlarge --box")
    n_vertices = n * p.n_vertices
    memory_fits(f"{n} rods x {p.n_vertices} vertices", BASE_BYTES + BYTES_PER_VERTEX * n_vertices,
                "lower --n-rods (default round(5.4 alpha)), --alpha or --vertices")
    vol = float(box[0] * box[1] * box[2]) * p.length**3
    phi = n * math.pi * d * d * p.length / 4.0 / vol
    if phi * p.alpha > MAX_PHI_ALPHA:
        fail(f"{n} rods of aspect ratio {p.alpha:g} would fill {phi:.3g} of the box (phi * alpha = "
             f"{phi * p.alpha:.3g}); random packing places at most phi * alpha ~ {MAX_PHI_ALPHA:g}: "
             f"lower --n-rods or enlarge --box")
    return n_vertices


def check_step_count(p, dt: float, source: str) -> None:
    """Refuse a run of more than :data:`MAX_STEPS` steps at step ``dt`` (s)."""
    steps = sum(stage_steps(s.duration, dt) for s in plan(p))
    if steps > MAX_STEPS:
        fail(f"the run needs {steps:.3g} steps at dt = {dt:.3g} s ({source}), more than {MAX_STEPS:.0e} "
             f"(weeks of computing); shorten --duration/--entangle-duration or lower --alpha")


#: bytes per vertex of the two checkpoints kept (state, warm-start impulses; the main job's
#: are 170 B per vertex each) and of initial.npz + final.npz, rounded up
DISK_BYTES_PER_VERTEX_FIXED = 2 * 400 + 2 * 100
#: the three PNG figures and the small files of a run
DISK_BYTES_FIXED = 1.0e6


def output_bytes(checked: CheckedProtocol) -> float:
    """Disk space a run needs (bytes): its frames (trajectory plus VTK, every --save-every),
    checkpoints, rod sets and figures."""
    V = float(checked.n_vertices)
    return float(checked.frames) * V * DISK_BYTES_PER_VERTEX_FRAME + V * DISK_BYTES_PER_VERTEX_FIXED \
        + DISK_BYTES_FIXED


def check_input_rods(p, explicit=()):
    """Load and check the --initial rod set, and measure its aspect ratio and rod length.

    A CSV is read in ``p.units`` (default m) with ``p.initial_diameter`` for a missing radius
    column (none is guessed); npz/zarr files record their own unit. Refuses an empty set,
    voxel units, a ``--units`` that contradicts an npz/zarr's recorded unit, a ``--diameter``
    that contradicts the file's radii, a mean rod length outside
    :data:`rodwarp.rodset.scale.PLAUSIBLE_LENGTH_M` (1e-5 to 100 m: most likely the wrong
    unit, the message names the measured length and the likely ``--units``), rods
    overlapping deeper than :data:`MAX_INPUT_OVERLAP` diameters (naming the deepest pair), an
    --alpha or --length among ``explicit`` that contradicts the input, and a set too large for
    memory.

    Returns
    -------
    rods : RodSet
        The input rods in metres.
    alpha : float
        Their aspect ratio, mean rod length over mean diameter.
    length : float
        Their mean rod length (m).
    """
    import numpy as np

    from rodwarp.rodset import UNITS, detect_contacts, load

    path = Path(p.initial)
    if not path.exists():
        fail(f"initial rod set not found: {path}; check the --initial path")
    from rodwarp.rodset.scale import PLAUSIBLE_LENGTH_M, check_diameter_agrees, unit_hint

    if p.units is not None and p.units not in ("m", "mm", "um"):
        if p.units == "voxel":
            fail("--units voxel: simulate runs in metres and a voxel has no size; convert the rods first "
                 "(RodSet.to_units('m', voxel_size=...)) or give the CSV's unit m, mm or um")
        fail(f"--units must be m, mm or um (the unit of the --initial CSV), got '{p.units}'")
    if p.initial_diameter is not None:
        number("--diameter", p.initial_diameter, gt=0, hint=f"the rod diameter in --units {p.units or 'm'}")
    csv = path.suffix.lower() == ".csv"
    # a CSV without a radius column is refused unless --diameter gives it: no diameter is guessed
    rods = load(path, diameter=p.initial_diameter, units=p.units) if csv else load(path)
    if rods.n_rods == 0:
        fail(f"--initial {path} holds no rods; nothing to simulate")
    if rods.units not in UNITS or rods.units == "voxel":
        fail(f"--initial {path} is in '{rods.units}' units; convert it to metres first "
             f"(RodSet.to_units('m', voxel_size=...))")
    if not csv and p.units is not None and p.units != rods.units:
        fail(f"--units {p.units}: {path} records its unit ('{rods.units}'); drop --units (it names a CSV's unit)")
    check_diameter_agrees(rods, p.initial_diameter, path)
    # rods of 1000 m are a CSV in mm read as metres far more often than real rods
    hint = unit_hint(rods)
    if hint:
        lo, hi = PLAUSIBLE_LENGTH_M
        fail(f"--initial {path}: {hint} (simulate takes rods {lo:g} to {hi:g} m long)")
    if rods.units != "m":
        rods = rods.to_units("m")
    memory_fits(f"--initial {path} ({rods.n_rods} rods, {rods.n_vertices} vertices)",
                BASE_BYTES + BYTES_PER_VERTEX * rods.n_vertices, "simulate a smaller rod set")
    d = float(np.mean(rods.diameters))
    from rodwarp.rodset.sanity import check_rod_geometry

    # zero-length rods, duplicates (refused here with their own message, not as an overlap of
    # 1 d) and a stray rod, which would stretch the container over its distance
    check_rod_geometry(rods, f"--initial {path}")
    lengths = rods.rod_lengths()
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
    return rods, alpha, length


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
