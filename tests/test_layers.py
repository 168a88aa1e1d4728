"""The package's import drawing (README, "Layout"; docs/extending.md): layers import downwards
only, no module imports another package's private module, and no modules import each other
in a circle.

    bottom  rodwarp.errors, rodwarp._util, rodwarp.arguments, rodwarp._warp, rodwarp.validation, rodwarp.kernels
    io      rodwarp.rodset (rod sets, formats, files, trajectories, run folders)
    peers   rodwarp.sim, rodwarp.analysis, rodwarp.ct, rodwarp.testing
    top     rodwarp.experiments
    face    rodwarp.cli

Every import statement in ``rodwarp/`` and ``kernels/`` is read (module level and inside
functions alike, since a deferred import is still a dependency); a module may import its own
subpackage and any lower layer, never a higher one nor a peer subpackage (the bottom layer's
few modules may use each other: errors under the rest).
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

LAYERS = {
    "rodwarp.errors": 0, "rodwarp._version": 0, "rodwarp._util": 0, "rodwarp.arguments": 0, "rodwarp._warp": 0, "rodwarp.validation": 0, "rodwarp.kernels": 0,
    "rodwarp.rodset": 1,
    "rodwarp.sim": 2, "rodwarp.analysis": 2, "rodwarp.ct": 2, "rodwarp.testing": 2,
    "rodwarp.experiments": 3,
    "rodwarp.cli": 4,
}


def _unit(module: str) -> str | None:
    """The layer unit (a key of LAYERS) a dotted module name belongs to."""
    for key in sorted(LAYERS, key=len, reverse=True):
        if module == key or module.startswith(key + "."):
            return key
    return None


def _modules():
    for path in sorted((ROOT / "rodwarp").rglob("*.py")):
        rel = path.relative_to(ROOT).with_suffix("")
        yield ".".join(p for p in rel.parts if p != "__init__"), path
    for path in sorted((ROOT / "kernels").glob("*.py")):
        yield "rodwarp.kernels" + ("" if path.stem == "__init__" else "." + path.stem), path


def _imports(path: Path, package: str):
    """(line, imported dotted module) for every import in the file."""
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield node.lineno, alias.name
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against the importing package
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            for alias in node.names:
                # `from rodwarp import _warp` imports a module; `from rodwarp.sim import Model` a name
                yield node.lineno, f"{base}.{alias.name}" if _unit(f"{base}.{alias.name}") else base


def upward_imports() -> list[str]:
    """Every import that goes up a layer or across to a peer subpackage, as 'file:line: a -> b'."""
    bad = []
    for module, path in _modules():
        mine = _unit(module)
        if mine is None:  # the package's own face (rodwarp/__init__.py re-exports every layer)
            continue
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for line, target in _imports(path, package):
            theirs = _unit(target)
            if theirs is None and target.startswith("rodwarp."):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {module} -> {target} (a module of no layer: add it "
                           f"to LAYERS)")
                continue
            if theirs is None or theirs == mine:
                continue  # not rodwarp (or the version from the package face), or its own unit
            # the bottom layer's modules build on each other; above it, peers stay apart
            if LAYERS[theirs] > LAYERS[mine] or (LAYERS[theirs] == LAYERS[mine] > 0):
                bad.append(f"{path.relative_to(ROOT)}:{line}: {module} -> {target}")
    return bad


def _is_package(dotted: str) -> bool:
    rel = dotted.split(".")[1:]
    if dotted.startswith("rodwarp.kernels"):
        return len(rel) == 1
    return (ROOT / "rodwarp" / Path(*rel) / "__init__.py").exists() if rel else True


def private_imports() -> list[str]:
    """Every import of a private module (a name part starting with ``_``) from outside the package
    that holds it, as 'file:line: a -> b': ``rodwarp.sim._bounds`` is for ``rodwarp.sim`` alone,
    ``rodwarp._util`` for all of ``rodwarp``; other packages go through public faces."""
    bad = []
    for module, path in _modules():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for line, target in _imports(path, package):
            if not target.startswith("rodwarp"):
                continue
            parts = target.split(".")
            for i, part in enumerate(parts):
                if part.startswith("_") and not part.startswith("__"):
                    owner = ".".join(parts[:i])
                    if i == len(parts) - 1 and not _is_package(owner):
                        owner = owner.rpartition(".")[0]  # a private name of a module: its package's own
                    if not (module == owner or module.startswith(owner + ".")):
                        bad.append(f"{path.relative_to(ROOT)}:{line}: {module} -> {target}")
                    break
    return bad


def import_cycles() -> list[list[str]]:
    """Every circle of modules that import each other (directly or around a loop), counting
    imports inside functions too: the strongly connected components of the import graph with
    more than one module. ``from pkg import name`` counts as importing ``pkg`` (its face) unless
    ``pkg.name`` is a module."""
    import sys

    mods = dict(_modules())

    def resolve(target: str):
        parts = target.split(".")
        for k in range(len(parts), 0, -1):
            if ".".join(parts[:k]) in mods:
                return ".".join(parts[:k])
        return None

    graph = {m: set() for m in mods}
    for module, path in mods.items():
        package = module if path.name == "__init__.py" else module.rpartition(".")[0]
        for _, target in _imports(path, package):
            for cand in (target, target.rpartition(".")[0]):
                r = resolve(cand) if cand.startswith("rodwarp") else None
                if r is not None:
                    if r != module:
                        graph[module].add(r)
                    break
    index, low, stack, on, out = {}, {}, [], set(), []
    sys.setrecursionlimit(max(10_000, sys.getrecursionlimit()))

    def visit(v):  # Tarjan's strongly connected components
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
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

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_import_circles():
    assert import_cycles() == []


def test_no_module_imports_from_a_layer_above_it_or_a_peer():
    assert upward_imports() == []


def test_no_module_imports_another_packages_private_module():
    assert private_imports() == []


if __name__ == "__main__":  # pragma: no cover - `python tests/test_layers.py` lists the offenders
    print("\n".join(upward_imports()) or "no upward imports")
    print("\n".join(private_imports()) or "no private cross-package imports")
    print("\n".join(" <-> ".join(c) for c in import_cycles()) or "no import circles")
