"""The imports of ``rodwarp.ct``: no import cycles among its modules, and no Warp.

Every import statement under ``rodwarp/ct`` is read with :mod:`ast` (module level, inside
functions and under ``TYPE_CHECKING`` alike: a deferred import is still a dependency).  An
import of a name through a lazy public face (``from rodwarp.ct.io import write_tiff``) counts
as an import of the module the face's ``_WHERE`` table loads it from, so that a face cannot
hide a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CT = ROOT / "rodwarp" / "ct"
#: what no module under rodwarp/ct may import, directly or inside a function
FORBIDDEN = ("warp", "rodwarp.kernels", "rodwarp.sim", "rodwarp._warp")


def _modules() -> dict[str, Path]:
    out = {}
    for path in sorted(CT.rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        out[".".join(p for p in rel.parts if p != "__init__")] = path
    return out


def _faces(mods: dict[str, Path]) -> dict[str, dict[str, str]]:
    """Package -> its lazy face's table (public name -> the module, dotted, that defines it)."""
    faces = {}
    for name, path in mods.items():
        if path.name != "__init__.py":
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Assign) and any(isinstance(t, ast.Name) and t.id == "_WHERE" for t in node.targets):
                faces[name] = {k: f"{name}.{v}" for k, v in ast.literal_eval(node.value).items()}
    return faces


def _imports(path: Path, package: str):
    """(line, module, names) of every import in the file; ``names`` empty for ``import x``."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name, ()
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against the importing package
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            yield node.lineno, base, tuple(a.name for a in node.names)


def _resolve(target: str, mods, faces, seen=()) -> str:
    """The defining module of ``target`` (a module, or ``face.name``), following lazy faces."""
    if target in mods:
        return target
    face, _, name = target.rpartition(".")
    if face in faces and name in faces[face] and target not in seen:
        return _resolve(faces[face][name], mods, faces, seen + (target,))
    return face if face in mods else target


def import_graph() -> dict[str, set[str]]:
    """Module -> the ct modules it imports (names through faces resolved to their modules)."""
    mods = _modules()
    faces = _faces(mods)
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for module, path in mods.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for _, base, names in _imports(path, package):
            targets = [f"{base}.{n}" for n in names] if names else [base]
            for t in targets:
                # `from pkg import _mod` imports the module; `from pkg import name` a name of pkg
                dep = _resolve(t, mods, faces)
                if dep not in mods:
                    dep = _resolve(base, mods, faces)
                if dep in mods and dep != module:
                    graph[module].add(dep)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out = []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def warp_imports() -> list[str]:
    """Every import of Warp, the kernels or the simulator under rodwarp/ct, as 'file:line: module'."""
    bad = []
    for module, path in _modules().items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for line, base, names in _imports(path, package):
            for t in [base] + [f"{base}.{n}" for n in names]:
                if any(t == f or t.startswith(f + ".") for f in FORBIDDEN):
                    bad.append(f"{path.relative_to(ROOT)}:{line}: {t}")
                    break
    return bad


def test_graph_sees_the_modules_and_their_deferred_imports():
    g = import_graph()
    assert "rodwarp.ct.segment._segment" in g and "rodwarp.ct.io._volume_io" in g
    # a function-level import and an import through a lazy face both count
    assert "rodwarp.ct.segment._prepare" in g["rodwarp.ct.segment._stages"]
    assert "rodwarp.ct.io._volume_meta" in g["rodwarp.ct.phantom._phantom"]


def test_cycle_finder_finds_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles_in_ct():
    assert cycles(import_graph()) == []


def test_ct_imports_no_warp():
    assert warp_imports() == []


def test_importing_ct_loads_no_warp():
    import subprocess
    import sys

    code = ("import sys, rodwarp.ct as ct; ct.segment_volume; ct.render_phantom; ct.read_volume; ct.run_segment; "
            "import rodwarp.ct.segment._stages, rodwarp.ct.segment._report, rodwarp.ct.phantom._phantom; "
            "print(sorted(m for m in sys.modules if m == 'warp' or m.startswith(('warp.', 'rodwarp.sim', "
            "'rodwarp.kernels'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.strip() == "[]"


if __name__ == "__main__":  # pragma: no cover - `python tests/test_ct_imports.py` lists the offenders
    print("\n".join(" <-> ".join(c) for c in cycles(import_graph())) or "no import cycles in rodwarp.ct")
    print("\n".join(warp_imports()) or "no warp in rodwarp.ct")
