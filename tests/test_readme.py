"""The README's examples run as printed (issue 49: the front page a newcomer reads).

Every command of the README's ``bash`` blocks, its Python example and the commands its prose
shows in backticks run here, in README order (later commands read what earlier ones wrote), in
a temporary folder, with this environment's ``rodwarp`` standing in for ``.venv/bin/rodwarp``
(the script beside ``sys.executable``: the quick start's ``.venv``, or ``.ci/run``'s fresh one).
The two quick-start lines install the package and run the main job or the whole suite, which
CI itself does (``.ci/run``): they are checked verbatim, not run. The extraction is
``scripts/readme_commands.py``'s, which runs the same README in a fresh clone.
"""

from __future__ import annotations

import shlex
import subprocess
import sys
import time
from pathlib import Path

import typer

from rodwarp.cli import app

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "scripts"))
from readme_commands import commands, inline_commands  # noqa: E402

README = (ROOT / "README.md").read_text()
QUICK_START = [
    "python3 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/rodwarp simulate --alpha 100 --freq 10",
    "python3 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/python -m pytest -q",
]
RODWARP = ".venv/bin/rodwarp"


def _rodwarp() -> list[str]:
    """This environment's ``rodwarp``: the script beside the interpreter (not resolved: a venv's
    python is a link to the base interpreter), else the module."""
    script = Path(sys.executable).parent / "rodwarp"
    return [str(script)] if script.exists() else [sys.executable, "-m", "rodwarp.cli"]


def _examples() -> list[tuple[str, str]]:
    """``(language, text)`` of every example the test runs: the bash lines after the quick
    start, the Python blocks, then the prose's commands."""
    ran = [(lang, text) for lang, text in commands(README) if not (lang == "bash" and text in QUICK_START)]
    return ran + [("bash", cmd) for cmd in inline_commands(README)]


def _expected(words: list[str], cwd: Path) -> list[Path]:
    """What a README command must leave behind: its ``--out``, analyze's ``analysis/`` beside
    its input, the phase diagram's ``alpha_star.csv`` in the sweep."""
    if "--help" in words or words[1] == "version":
        return []
    if "--out" in words:
        out = cwd / words[words.index("--out") + 1]
        return [out] + ([out / "results.csv"] if words[1] == "sweep" else [out / "summary.json"]
                        if words[1] in ("simulate", "segment") else [])
    target = cwd / words[2]
    return {"analyze": [target / "analysis" / "summary.json"],
            "phase-diagram": [target / "alpha_star.csv"]}[words[1]]


def test_the_readme_is_a_two_minute_read():
    assert len(README.splitlines()) <= 120, len(README.splitlines())


def test_the_quick_start_is_the_two_commands_verbatim():
    bash = [text for lang, text in commands(README) if lang == "bash"]
    assert bash[:2] == QUICK_START


def test_every_command_has_one_example_and_each_uses_the_environments_rodwarp():
    lines = [text for lang, text in _examples() if lang == "bash"]
    for cmd in lines:  # no line relies on an activated environment
        assert shlex.split(cmd, comments=True)[0] == RODWARP, cmd
    shown = [shlex.split(cmd)[1] for cmd in lines if "--help" not in cmd]
    assert sorted(shown) == sorted(typer.main.get_command(app).commands), shown


def test_every_readme_example_runs_as_printed(tmp_path):
    """All the examples, in order, in one folder: exit 0, the result line on stdout, and the
    outputs each command promises."""
    took = []
    for lang, text in _examples():
        t0 = time.perf_counter()
        if lang == "python":
            (tmp_path / "readme_example.py").write_text(text)
            argv = [sys.executable, "readme_example.py"]
        else:
            words = shlex.split(text, comments=True)
            argv = _rodwarp() + words[1:]
        r = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=600)
        took.append((text.splitlines()[0][:60], round(time.perf_counter() - t0, 1)))
        assert r.returncode == 0, f"{text}\nexited {r.returncode}:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}"
        if lang == "python":
            # the upper rod comes to rest on the lower one: one contact, its centreline about a
            # diameter above the floor (it sags a little over the lower rod)
            n, z = r.stdout.split()[-2:]
            assert int(n) == 1 and 0.013 < float(z) < 0.0155, r.stdout
            continue
        for path in _expected(words, tmp_path):
            assert path.exists(), f"{text}: no {path.relative_to(tmp_path)}"
        if "--help" not in words:  # the result line, alone on stdout
            out = [ln for ln in r.stdout.splitlines() if ln.strip()]
            assert len(out) == 1, (text, r.stdout)
            assert out[0].startswith("rodwarp ") if words[1] == "version" else " -> " in out[0], (text, out)
    print("README examples (s):", took)
