"""Run the README as a newcomer would: a fresh clone, the two quick-start commands, then every
command and Python example the README shows, in order, as written (then the commands its prose
shows in backticks). ``tests/test_readme.py`` runs the same examples in the test suite, without
the clone and the install; it shares :func:`commands` and :func:`inline_commands`. Writes
``benchmarks/results/readme_commands.md`` (each command, exit code, wall time, last line).

    python scripts/readme_commands.py [--clone DIR] [--skip-tests]

The clone is made from this repository's committed ``main`` (``git clone``), so uncommitted
work is not what is tested. The quick-start commands create ``.venv`` in the clone; the later
commands run in the clone's root with ``.venv/bin`` first on ``PATH``. A line ending in ``&``
(a background process, such as a Dask scheduler) is started in the background, given a few
seconds, and stopped when everything else is done.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def blocks(readme: str) -> list[tuple[str, str]]:
    """``(language, text)`` of every fenced code block, in order."""
    return [(m.group(1), m.group(2)) for m in re.finditer(r"```(\w*)\n(.*?)```", readme, re.S)]


def commands(readme: str) -> list[tuple[str, str]]:
    """``("bash", line)`` for each command line of a bash block, ``("python", text)`` for each
    Python block; the layout tree (a text block) is not a command."""
    out = []
    for lang, text in blocks(readme):
        if lang == "bash":
            out += [("bash", ln.strip()) for ln in text.splitlines() if ln.strip() and not ln.strip().startswith("#")]
        elif lang == "python":
            out.append(("python", text))
    return out


def inline_commands(readme: str) -> list[str]:
    """The ``.venv/bin/rodwarp ...`` commands the README's prose shows in backticks (outside its
    code blocks), in order: they must run as printed too."""
    prose = re.sub(r"```\w*\n.*?```", "", readme, flags=re.S)
    return re.findall(r"`(\.venv/bin/rodwarp [^`]*)`", prose)


def _cpu_model() -> str:
    """The processor the table was made on (the benchmarks' own provenance helper)."""
    sys.path.insert(0, str(ROOT))
    from benchmarks.common import cpu_model

    return cpu_model()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--clone", default=None, help="Where to clone (default: a new temporary folder).")
    ap.add_argument("--skip-tests", action="store_true", help="Install the test extra but do not run the tests.")
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "readme_commands.md"))
    args = ap.parse_args(argv)
    clone = Path(args.clone or tempfile.mkdtemp(prefix="rodwarp_readme_")) / "rodwarp"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True)
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=clone, capture_output=True,
                          text=True).stdout.strip()
    env = dict(os.environ)
    env["PATH"] = f"{clone / '.venv' / 'bin'}{os.pathsep}{env['PATH']}"
    env.pop("VIRTUAL_ENV", None)
    rows, background = [], []
    readme = (clone / "README.md").read_text()
    for lang, cmd in commands(readme) + [("bash", c) for c in inline_commands(readme)]:
        if args.skip_tests and "pytest" in cmd:
            cmd = cmd.replace("&& .venv/bin/python -m pytest -q", "&& echo 'tests skipped (--skip-tests)'")
        shown = cmd if lang == "bash" else "python: " + cmd.strip().splitlines()[0] + " ..."
        print(f"$ {shown}", flush=True)
        t = time.perf_counter()
        if lang == "bash" and cmd.split("#")[0].rstrip().endswith("&"):
            p = subprocess.Popen(["bash", "-c", cmd.split("#")[0].rstrip()[:-1]], cwd=clone, env=env,
                                 stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
            background.append(p)
            time.sleep(5)
            rc, last = (None if p.poll() is None else p.returncode), "started in the background"
        else:
            argv_ = ["bash", "-c", cmd] if lang == "bash" else [str(clone / ".venv" / "bin" / "python"), "-c", cmd]
            r = subprocess.run(argv_, cwd=clone, env=env, capture_output=True, text=True)
            rc = r.returncode
            # the result line (stdout) when there is one, else the last word on stderr (the error)
            out = [ln for ln in r.stdout.splitlines() if ln.strip() and "━" not in ln]
            err = [ln for ln in r.stderr.splitlines() if ln.strip() and "━" not in ln]
            lines = out if out and rc == 0 else (err or out)
            last = lines[-1].strip() if lines else ""
            if rc != 0:
                print(r.stdout[-2000:], r.stderr[-2000:], flush=True)
        wall = time.perf_counter() - t
        rows.append((shown, rc, wall, last))
        print(f"  -> exit {rc}, {wall:.1f} s: {last[:200]}", flush=True)
    for p in background:
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGTERM)
            p.wait(timeout=30)
    failed = sum(1 for _, rc, _, _ in rows if rc not in (0, None))
    lines = ["# The README, run as written", "",
             f"Generated by `python scripts/readme_commands.py` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}"
             f" on {platform.node()} ({_cpu_model()}, {os.cpu_count()} cores), "
             f"Python {platform.python_version()}: a fresh `git clone` of main at {head}, the two quick-start "
             "commands, then every command and Python example of the README in order, in the clone's root with "
             "`.venv/bin` first on PATH. Background lines (`&`) are started, given 5 s, and stopped at the end.", "",
             f"**{len(rows) - failed} of {len(rows)} ran (exit 0 or running in the background), {failed} failed.**", "",
             "| command | exit | wall (s) | last line |", "| --- | --- | --- | --- |"]
    for shown, rc, wall, last in rows:
        cell = last.replace("|", "/").replace(str(clone), "$CLONE")[:220]
        lines.append(f"| `{shown.replace('|', '/')}` | {'bg' if rc is None else rc} | {wall:.1f} | {cell} |")
    Path(args.out).write_text("\n".join(lines) + "\n")
    print(f"wrote {args.out}: {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
