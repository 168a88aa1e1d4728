"""Every numeric option of every command, fed NaN, +-inf, 0, a negative, a tiny and a huge value.

Each option states its range once, beside it in its command's parameters dataclass
(:class:`rodwarp.validation.Range` in the field's metadata). Walked through the real command
line (:func:`rodwarp.cli.main`), with the command's work replaced by a stub, every value must
be either taken (the stub is reached) or refused in one ``error:`` line with exit 2, never a
traceback; a value outside the stated range must be refused, naming the option; a value
inside it may only be refused by a check that ties options together (not by the range).
"""

from __future__ import annotations

import numpy as np
import pytest
import typer
from typer.main import get_command

import rodwarp.analysis
import rodwarp.ct
import rodwarp.experiments
from rodwarp.analysis import AnalyzeOptions
from rodwarp.cli import app, main
from rodwarp.ct import PhantomOptions, SegmentOptions
from rodwarp.experiments import ProtocolParams, SweepSpec
from rodwarp.validation import Range

#: the values every numeric option is fed
VALUES = ("nan", "inf", "-inf", "0", "-1", "1e-300", "1e300")
#: more values for whole-number options (a float is a usage error there)
WHOLE_VALUES = ("0", "-1", "1", str(10**30))
#: the stub's exit code: the command got past every check to its work
TAKEN = 99

#: each command's parameters dataclass, and its options named otherwise than their fields
COMMANDS = {
    "simulate": (ProtocolParams, {"diameter": "initial_diameter"}),
    "analyze": (AnalyzeOptions, {}),
    "segment": (SegmentOptions, {}),
    "phantom": (PhantomOptions, {}),
    "sweep": (SweepSpec, {"alpha": "alphas", "freq": "freqs", "gravity": "gravities", "static_load": "static_loads"}),
}
#: the command's own options that are not dataclass fields, with their ranges
OWN = {
    ("sweep", "workers"): Range(ge=1, whole=True),  # and at most the cores and memory: run_sweep's check
    ("sweep", "seeds"): Range(ge=1, le=10_000, whole=True),
    ("phantom", "shape"): Range(ge=2, le=100_000, whole=True),  # rodwarp.ct.phantom._checks.SHAPE_RANGE
}
#: the options each simulate option needs to apply at all (else "only applies with ..." refuses it)
CONTEXT = {
    **{k: ["--contact-law", "imc"] for k in ("imc_delta", "imc_nu", "imc_stiffness")},
    **{k: ["--protocol", "lab"] for k in ("container_radius", "fill_height", "press_duration")},
    "strains": ["--protocol", "lab"],
    **{k: ["--protocol", "excitation"] for k in ("container_diameter", "container_height", "tube_diameter",
                                                 "pour_duration", "lift_duration")},
}
#: work functions replaced by the stub
WORK = [(rodwarp.experiments, "run_protocol"), (rodwarp.experiments, "run_sweep"), (rodwarp.analysis, "analyze"),
        (rodwarp.ct, "run_segment"), (rodwarp.cli, "make_phantom")]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """A rod set to analyse and a small CT stack to segment."""
    import tifffile

    from rodwarp.rodset import RodSet

    d = tmp_path_factory.mktemp("ranges")
    s = np.linspace(-0.5, 0.5, 10)
    RodSet.from_polylines([np.stack([s, 0 * s + 0.3 * k, 0 * s + 0.2], 1) for k in range(3)],
                          radii=0.01).save(d / "rods.npz")
    vol = np.zeros((24, 24, 24), np.uint16)
    vol[10:14, 10:14, 2:22] = 3000
    tifffile.imwrite(d / "stack.tif", vol + 100)
    return d


def _numeric_options(command: str):
    """(option name, python name, whole, nargs) of each numeric option of ``command``."""
    click_cmd = get_command(app).commands[command]
    out = []
    for p in click_cmd.params:
        if not p.opts or not p.opts[0].startswith("--"):
            continue
        base = _number_type(p.type_descriptor.annotation)
        text_numbers = command == "sweep" and p.name in COMMANDS["sweep"][1] or p.name in ("box", "strains")
        if base is not None or text_numbers:
            out.append((p.opts[0], p.name, base is int, p.nargs))
    return out


def _number_type(tp):
    """float or int for an option annotated so (optional, or a tuple of them), else None."""
    import typing

    args = [a for a in typing.get_args(tp) if a is not type(None) and a is not Ellipsis]
    if tp in (float, int):
        return tp
    if args and all(a in (float, int) for a in args):
        return args[0]
    return None


def _range(command: str, name: str) -> Range | None:
    cls, renamed = COMMANDS[command]
    if (command, name) in OWN:
        return OWN[(command, name)]
    from dataclasses import fields

    field = renamed.get(name, name)
    if command == "sweep" and field not in {f.name for f in fields(cls)}:
        cls = ProtocolParams  # a simulate option the sweep passes to every point (--save-every)
    return next((f.metadata.get("range") for f in fields(cls) if f.name == field), None)


def _base(command: str, inputs, tmp) -> list[str]:
    return {"simulate": ["simulate", "--device", "cpu", "--quiet", "--out", str(tmp / "o")],
            "analyze": ["analyze", str(inputs / "rods.npz"), "--quiet", "--out", str(tmp / "a")],
            "segment": ["segment", str(inputs / "stack.tif"), "--voxel-size", "1", "--units", "voxel", "--quiet",
                        "--out", str(tmp / "s")],
            "phantom": ["phantom", "random", "--shape", "32", "32", "32", "--out", str(tmp / "p.tif")],
            "sweep": ["sweep", "--out", str(tmp / "w"), "--quiet"]}[command]


def _cases():
    for command in COMMANDS:
        for opt, name, whole, nargs in _numeric_options(command):
            for v in (WHOLE_VALUES if whole else VALUES):
                yield pytest.param(command, opt, name, whole, nargs, v, id=f"{command}{opt}={v}")


def test_every_numeric_option_states_its_range():
    missing = [f"{c} {opt}" for c in COMMANDS for opt, name, *_ in _numeric_options(c) if _range(c, name) is None]
    assert not missing, f"options without a stated Range: {missing}"


@pytest.mark.parametrize("command, opt, name, whole, nargs, value", list(_cases()))
def test_option_value_is_taken_or_refused_in_one_line(command, opt, name, whole, nargs, value, inputs, tmp_path,
                                                      monkeypatch, capsys):
    def stub(*a, **k):
        raise typer.Exit(TAKEN)

    for mod, attr in WORK:
        monkeypatch.setattr(mod, attr, stub)
    args = _base(command, inputs, tmp_path)
    if opt == "--shape":
        args = [a for a in args if a not in ("--shape", "32")]
    args += CONTEXT.get(name, []) if command == "simulate" else []
    given = [value] * nargs if nargs > 1 else [value]
    if name == "box":
        given = [f"1,{value},2.5"]
    rc = main([*args, opt, *given])
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip() and not ln.startswith("note:")]
    assert rc in (2, TAKEN), (rc, err)
    assert not any("Traceback" in ln or "internal error" in ln for ln in err), err
    rng = _range(command, name)
    try:
        x = float(value)
    except ValueError:  # pragma: no cover - every value here parses
        x = None
    inside = rng is not None and x is not None and rng.contains(int(x) if whole and x == int(x) else x)
    if rc == 2:
        assert len(err) == 1 and err[0].startswith("error:"), err
    if not inside:  # outside the stated range: refused, naming the option
        assert rc == 2, f"{opt} {value} is outside {rng.text() if rng else '?'} but was taken"
        assert opt in err[0] or "Invalid value" in err[0], err[0]
    elif rc == 2:  # inside the range: only a check tying options together may refuse it
        assert f"{opt} must be" not in err[0], err[0]
