"""The package's layout, read from its source: packages by layer with imports pointing one
way (down), no import circles, an exact reference that depends on the scene model alone,
modules of one idea each, and the old import paths kept for one release.

Imports are read with ``ast`` from every module, including those inside functions (a
lazy import is still an arrow), so nothing here needs GL."""

import ast
import importlib
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "dvr_gl"

# Top to bottom; a module may import its own layer and the layers below it. Layers in
# one tuple are peers: independent of each other.
LAYERS = [
    ("dvr_gl", "dvr_gl.__main__"),
    ("dvr_gl.frontends",),
    ("dvr_gl.bench",),
    ("dvr_gl.rendering",),
    ("dvr_gl.reference",),
    ("dvr_gl.techniques",),
    ("dvr_gl.gl", "dvr_gl.formats", "dvr_gl.data"),
    ("dvr_gl.model",),
    ("dvr_gl.util", "dvr_gl.metrics", "dvr_gl._compat", "dvr_gl._version", "dvr_gl.shaders"),
]

# The exact integrator and the helpers it reads the contract through.
EXACT = "dvr_gl.reference.exact"
EXACT_MAY_IMPORT = ("dvr_gl.model", "dvr_gl.util", "dvr_gl.reference.exact", "dvr_gl.reference.common",
                    "dvr_gl.reference.shading", "dvr_gl.reference.mesh_rays")

# Modules over MAX_LINES, each one idea that would read worse cut in two.
MAX_LINES = 600
ONE_IDEA = {
    "dvr_gl.reference.exact_one": "the exact integrator of the contract, grids and meshes",
    "dvr_gl.model.preintegration": "the pre-integration table and its error bounds",
    "dvr_gl.techniques.splat": "splatting: its two kernels share the plan, sheets and drawing",
    "dvr_gl.bench.vtk_peer": "the same scene through VTK",
}


def _modules():
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        is_package = parts[-1] == "__init__"
        name = ".".join(parts[:-1] if is_package else parts)
        out[name] = (path, is_package)
    return out


MODULES = _modules()


def _target(module, is_package, node):
    if node.level == 0:
        return node.module
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(module):
    """The dvr_gl modules that ``module`` imports, and the top-level names of the other
    packages it imports. A string that names a dvr_gl module (``importlib.import_module``,
    a registry of techniques by name) counts as an import, except in the table of old
    paths (``_compat``), whose strings are the point of it."""
    path, is_package = MODULES[module]
    ours, theirs = set(), set()
    for node in ast.walk(ast.parse(path.read_text())):
        if (isinstance(node, ast.Constant) and node.value in MODULES and "." in node.value
                and module != "dvr_gl._compat"):
            names = [node.value]
        elif isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _target(module, is_package, node)
            # `from package import module` imports the module; `from module import name`, the module
            names = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in node.names]
        else:
            continue
        for name in names:
            if name.split(".")[0] != "dvr_gl":
                theirs.add(name.split(".")[0])
                continue
            while name not in MODULES:             # dvr_gl.x.attribute -> dvr_gl.x
                name = name.rpartition(".")[0]
            if name != module:
                ours.add(name)
    return ours, theirs


GRAPH = {m: _imports(m)[0] for m in MODULES}


def _layer(module):
    for rank, layer in enumerate(LAYERS):
        for top in layer:
            if module == top or (top != "dvr_gl" and module.startswith(top + ".")):
                return rank, top
    raise AssertionError(f"{module} is in no layer of tests/test_layout.py")


def _cycles(graph):
    """Strongly connected components of more than one module (Tarjan)."""
    index, low, stack, on_stack, found = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def _closure(start):
    seen, todo = set(), [start]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(GRAPH[m])
    return seen


def test_the_reader_sees_imports():
    # the checks below mean something only if the graph is read right
    assert "dvr_gl.model.scene" in GRAPH["dvr_gl.techniques.raycast"]
    assert "dvr_gl.rendering.tolerance" in GRAPH["dvr_gl.rendering.renderer"]   # a lazy import
    assert "dvr_gl.techniques.raycast" in GRAPH["dvr_gl.techniques"]            # by name
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_circles():
    assert _cycles(GRAPH) == []


def test_imports_point_down_the_layers():
    wrong = []
    for module, targets in GRAPH.items():
        rank, top = _layer(module)
        for target in targets:
            target_rank, target_top = _layer(target)
            if target_rank < rank or (target_rank == rank and target_top != top):
                wrong.append(f"{module} -> {target}")
    assert wrong == []


def test_exact_reference_depends_on_the_model_alone():
    closure = _closure(EXACT)
    assert {m for m in closure if not m.startswith(EXACT_MAY_IMPORT)} == set()
    assert not any(m.startswith(("dvr_gl.techniques", "dvr_gl.gl", "dvr_gl.rendering")) for m in closure)
    third_party = set().union(*(_imports(m)[1] for m in closure))
    assert "moderngl" not in third_party and "glcontext" not in third_party


def test_exact_reference_loads_no_gl_and_no_technique():
    code = ("import sys, dvr_gl.reference.exact\n"
            "bad = sorted(m for m in sys.modules if m.startswith(('dvr_gl.techniques', 'dvr_gl.gl', "
            "'dvr_gl.rendering', 'moderngl')))\n"
            "print(bad)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.strip() == "[]"


def test_bench_is_off_the_runtime_path():
    runtime = set().union(*(_closure(m) for m in MODULES
                            if not m.startswith(("dvr_gl.bench", "dvr_gl.frontends.cli", "dvr_gl.__main__"))))
    assert {m for m in runtime if m.startswith("dvr_gl.bench")} == set()


def test_modules_are_one_idea():
    long = {}
    for module, (path, _) in MODULES.items():
        lines = len(path.read_text().splitlines())
        if lines > MAX_LINES and module not in ONE_IDEA:
            long[module] = lines
    assert long == {}


@pytest.mark.parametrize("old", sorted(importlib.import_module("dvr_gl._compat").MOVED))
def test_old_import_paths_still_work_with_a_warning(old):
    from dvr_gl import _compat
    new = _compat.MOVED[old]
    sys.modules.pop(old, None)
    with pytest.warns(DeprecationWarning, match=new.replace(".", r"\.")):
        module = importlib.import_module(old)
    assert module is importlib.import_module(new)
    assert module.__name__ == new                  # the module keeps its own name and spec
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        importlib.import_module(new)               # the new path is quiet


def test_every_package_directory_is_listed_for_the_build():
    """pyproject.toml names every directory of Python modules and of shaders as a package
    (setuptools warns of, and may one day drop, a directory of package data it was not
    told of)."""
    tomllib = pytest.importorskip("tomllib")     # Python 3.11
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {"dvr_gl.shaders"} | {f"dvr_gl.shaders.{d.name}" for d in (ROOT / "shaders").iterdir() if d.is_dir()}
    found |= {".".join(p.parent.relative_to(ROOT).parts) for p in PACKAGE.rglob("__init__.py")}
    assert listed == found
