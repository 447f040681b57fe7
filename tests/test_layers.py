"""The package's import layers hold: core < io < shared services < pillars < cli/studio/scale.

Every ``import`` in ``src/biomorph`` is read from the syntax tree, function-level ones
included, and resolved to the module it names. A module may import only from its own layer
or below, modules may not import each other in a cycle, and only the lazy loaders listed in
``DYNAMIC_OK`` may use ``importlib.import_module``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SRC = Path(__file__).resolve().parents[1] / "src"
PKG = SRC / "biomorph"

PILLARS = ("creature", "tree", "motion", "leaf")

# Modules that load sub-packages by name on purpose (optional pillars); package __init__
# modules may also do it for lazy attribute access.
DYNAMIC_OK = {"biomorph.pillars"}


def layer_of(module: str) -> int:
    """0 core, 1 io, 2 shared services, 3 pillars, 4 front ends (cli, demo, studio, scale,
    and each pillar's ``cli`` and ``demo`` modules)."""
    parts = module.split(".")
    if module == "biomorph":
        return 0  # only __version__ and a lazy __getattr__ (no static imports)
    top = parts[1]
    if top in ("core", "errors", "progress"):
        return 0
    if top == "io":
        return 1
    if top in ("_cli", "render", "report", "pillars"):
        return 2
    if top in PILLARS:
        # a pillar's command group and demo are front ends that live with their pillar
        return 4 if len(parts) > 2 and parts[2] in ("cli", "demo") else 3
    if top in ("cli", "demo", "foundation_demo", "inspect", "studio", "scale", "__main__"):
        return 4
    raise AssertionError(f"module {module} has no layer: add it to tests/test_layers.py")


def _modules() -> dict[str, Path]:
    out = {}
    for path in PKG.rglob("*.py"):
        rel = path.relative_to(SRC).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__":
            parts.pop()
        out[".".join(parts)] = path
    return out


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The longest known module prefix of a dotted name (``biomorph.io.bvh.read`` -> io.bvh)."""
    parts = name.split(".")
    while parts:
        cand = ".".join(parts)
        if cand in MODULES:
            return cand
        parts.pop()
    return None


def imports_of(module: str) -> list[tuple[str, int]]:
    """(imported biomorph module, line) for every import statement in ``module``."""
    path = MODULES[module]
    tree = ast.parse(path.read_text(encoding="utf-8"))
    is_pkg = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split(".")
                base = base if is_pkg else base[:-1]
                base = base[: len(base) - (node.level - 1)]
                prefix = ".".join(base + ([node.module] if node.module else []))
            else:
                prefix = node.module or ""
            # ``from pkg import mod`` runs ``pkg/__init__`` too: an edge to both
            subs = [f"{prefix}.{a.name}" for a in node.names]
            names = [prefix] + [n for n in subs if n in MODULES]
        for name in names:
            if name == "biomorph" or name.startswith("biomorph."):
                target = _resolve(name)
                if target and target != module:
                    out.append((target, node.lineno))
    return sorted(set(out))


def _dynamic_imports(module: str) -> list[int]:
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    return [
        n.lineno
        for n in ast.walk(tree)
        if isinstance(n, ast.Attribute) and n.attr == "import_module"
    ]


def test_every_module_has_a_layer():
    for module in MODULES:
        layer_of(module)


def test_no_upward_imports():
    bad = []
    for module in sorted(MODULES):
        mine = layer_of(module)
        for target, line in imports_of(module):
            if layer_of(target) > mine:
                bad.append(
                    f"{MODULES[module].relative_to(SRC)}:{line}: {module} (layer {mine}) "
                    f"imports {target} (layer {layer_of(target)})"
                )
    assert not bad, "upward imports:\n" + "\n".join(bad)


def test_no_import_cycles():
    graph = {m: sorted({t for t, _ in imports_of(m)}) for m in MODULES}
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    cycles: list[list[str]] = []
    counter = [0]

    def strong(v: str) -> None:  # Tarjan, iterative enough for this graph's depth
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                strong(w)
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
                cycles.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    assert not cycles, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in cycles)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_no_dynamic_imports(module):
    if module in DYNAMIC_OK or MODULES[module].name == "__init__.py":
        return  # package __init__ modules may load their submodules lazily
    lines = _dynamic_imports(module)
    assert not lines, f"{module} uses importlib.import_module at lines {lines}"


def test_readme_layout_names_every_package_and_pillar_module():
    readme = (SRC.parent / "README.md").read_text(encoding="utf-8")
    block = readme[readme.index("## Layout") :]
    block = block[: block.index("\n## ", 1)]
    missing = []
    for path in sorted(PKG.iterdir()):
        name = path.name
        if path.is_dir() and (path / "__init__.py").exists():
            if f"{name}/" not in block:
                missing.append(f"{name}/")
        elif path.suffix == ".py" and name not in ("__init__.py", "__main__.py"):
            if path.stem not in block:
                missing.append(name)
    for pillar in PILLARS:
        for path in sorted((PKG / pillar).glob("*.py")):
            if path.stem.startswith("_") or path.stem in ("cli", "demo", "plots"):
                continue
            if path.stem not in block:
                missing.append(f"{pillar}/{path.name}")
    assert not missing, f"README layout does not mention: {', '.join(missing)}"


@pytest.mark.parametrize("package", ["core", "io", *PILLARS])
def test_no_public_name_is_shadowed_by_a_submodule(package):
    """A function exported under a submodule's name (``creature.export`` beside
    ``creature/export.py``) is replaced by the module once anything imports that module."""
    import importlib

    mod = importlib.import_module(f"biomorph.{package}")
    folder = PKG / package
    clash = [
        name
        for name in getattr(mod, "__all__", [])
        if (folder / f"{name}.py").exists() or (folder / name / "__init__.py").exists()
    ]
    assert not clash, f"biomorph.{package} exports {clash}, also submodule names"
