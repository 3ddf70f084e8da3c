"""The import rule of docs/architecture.md, checked on the AST of every project module.

Each module belongs to a room (its folder under paramlod/; ``functions/``, ``kernels/`` and
``surfels/`` are installed as ``paramlod.functions``, ``paramlod.kernels`` and ``paramlod.surfels``).
An import is allowed when the importer's room may import the imported room (ALLOWED below, the
table of the architecture document). Also checked: no project import inside a function, no import
circle among project modules, and within ``renderers`` a renderer imports only the kit.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = {"paramlod": ROOT / "paramlod", "paramlod.functions": ROOT / "functions",
           "paramlod.kernels": ROOT / "kernels", "paramlod.surfels": ROOT / "surfels"}

BASE = {"core", "errors"}
ALLOWED = {
    "errors": set(),
    "core": {"errors"},
    "kernels": set(),
    "device": BASE | {"kernels"},
    "function": BASE | {"device", "kernels"},
    "dsl": BASE | {"device", "function"},
    "scene": BASE | {"function", "dsl"},
    "dmri": BASE | {"function", "dsl", "scene", "dmri.sh"},
    "dmri.sh": {"errors"},   # SH bookkeeping (numpy, scipy): part of the plugins' public API
    "lod": BASE | {"device", "kernels", "function", "dsl", "scene"},
    "renderers": BASE | {"device", "kernels", "function", "dsl", "scene", "lod"},
    "meshlod": BASE | {"device", "kernels", "function", "dsl", "scene", "lod", "renderers"},
    "surfels": BASE | {"device", "kernels", "function", "dsl", "scene", "lod", "renderers"},
    "pipeline": BASE | {"device", "kernels", "function", "dsl", "scene", "lod", "renderers", "dmri",
                        "dmri.sh", "meshlod", "surfels"},
    # the public face, commands, the viewer and offline build tools may import anything
    "public": None, "app": None, "viewer": None, "surfels.build": None,
    # plugins see the public API only (and each other)
    "functions": {"public", "dsl", "errors", "functions", "dmri.sh"},
}
# what a renderer may import from renderers/ (occlusion: the depth-pyramid culling any key-buffer renderer can use)
KIT = {"registry", "targets", "gl_targets", "aa", "shading", "sampling", "occlusion"}
# a renderer's own parts in files of their own: only that renderer imports them
PARTS = {"tess_grid": "tess"}


def modules() -> dict[str, Path]:
    out = {}
    for pkg, folder in FOLDERS.items():
        for path in folder.rglob("*.py"):
            rel = path.relative_to(folder).with_suffix("")
            parts = [p for p in rel.parts if p != "__init__"]
            out[".".join([pkg, *parts])] = path
    return out


MODULES = modules()


def room(mod: str) -> str:
    parts = mod.split(".")
    if mod in ("paramlod", "paramlod.views"):   # the package and its camera-set face
        return "public"
    if mod == "paramlod.__main__":
        return "app"
    if parts[1] == "surfels":
        return "surfels.build" if len(parts) > 2 and parts[2] == "build" else "surfels"
    if mod == "paramlod.dmri.sh":
        return "dmri.sh"
    return parts[1]


def resolve(mod: str, node: ast.ImportFrom | ast.Import) -> list[str]:
    """Project modules an import statement names (a name imported from a package counts as the
    submodule when one exists, else as the package)."""
    is_pkg = MODULES[mod].name == "__init__.py"
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
        return [n for n in names if n == "paramlod" or n.startswith("paramlod.")]
    base = node.module or ""
    if node.level:
        pkg = mod.split(".") if is_pkg else mod.split(".")[:-1]
        pkg = pkg[:len(pkg) - (node.level - 1)]
        base = ".".join(pkg + ([base] if base else []))
    if not (base == "paramlod" or base.startswith("paramlod.")):
        return []
    out = []
    for a in node.names:
        sub = f"{base}.{a.name}"
        out.append(sub if sub in MODULES else base)
    return out


def imports():
    """(importer, imported, line, inside a function) for every project import."""
    found = []
    for mod, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))

        def walk(node, in_function):
            for child in ast.iter_child_nodes(node):
                inside = in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
                if isinstance(child, (ast.Import, ast.ImportFrom)):
                    for target in resolve(mod, child):
                        if target in MODULES or target == "paramlod":
                            found.append((mod, target, child.lineno, in_function))
                walk(child, inside)

        walk(tree, False)
    return found


IMPORTS = imports()


def _where(mod, line):
    return f"{MODULES[mod].relative_to(ROOT)}:{line}"


def test_rooms_import_only_what_the_table_allows():
    bad = []
    for src, dst, line, _ in IMPORTS:
        a, b = room(src), room(dst)
        allowed = ALLOWED[a]
        if a == b or allowed is None or b in allowed:
            continue
        bad.append(f"{_where(src, line)}: {src} ({a}) imports {dst} ({b})")
    assert not bad, "imports against the table:\n" + "\n".join(bad)


def test_a_renderer_imports_only_the_kit():
    bad = []
    for src, dst, line, _ in IMPORTS:
        if room(src) == room(dst) == "renderers":
            s, d = src.split(".")[-1], dst.split(".")[-1]
            if d in KIT or dst == "paramlod.renderers" or s in KIT or s == "renderers":
                continue
            if s.endswith("_reference"):   # a numpy twin imports what it mirrors
                continue
            if PARTS.get(d) == s:   # a renderer imports its own part
                continue
            bad.append(f"{_where(src, line)}: {src} imports another renderer, {dst}")
    assert not bad, "\n".join(bad)


def test_no_project_import_inside_a_function():
    bad = [f"{_where(src, line)}: {src} imports {dst} inside a function" for src, dst, line, late in IMPORTS if late]
    assert not bad, "\n".join(bad)


def test_no_import_circle():
    graph: dict[str, set[str]] = {m: set() for m in MODULES}
    for src, dst, _, _ in IMPORTS:
        if dst != src and dst in graph and not dst.startswith(src + "."):
            graph[src].add(dst)
    # a package's __init__ importing its own submodules is how packages re-export
    state, stack, cycles = {}, [], []

    def visit(m):
        state[m] = 1
        stack.append(m)
        for n in sorted(graph[m]):
            if state.get(n) == 1:
                cycles.append(stack[stack.index(n):] + [n])
            elif n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)
    assert not cycles, "import circles:\n" + "\n".join(" -> ".join(c) for c in cycles[:10])


def test_no_name_shadows_its_module():
    """``paramlod.X`` is a module or a public name, never a name hiding the module X."""
    import importlib

    bad = []
    for mod in MODULES:
        parent, _, name = mod.rpartition(".")
        if not parent or parent not in MODULES or MODULES[parent].name != "__init__.py":
            continue
        pkg = importlib.import_module(parent)
        value = getattr(pkg, name, None)
        if value is not None and not isinstance(value, type(pkg)):
            bad.append(f"{parent}.{name} is {type(value).__name__}, hiding the module {mod}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("mod", ["paramlod.pipeline.driver", "paramlod.renderers.points"])
def test_the_checker_sees_the_frame_path(mod):
    """The walk is not vacuous: the modules of one frame are found and import project modules."""
    assert mod in MODULES
    assert any(src == mod for src, _, _, _ in IMPORTS)
