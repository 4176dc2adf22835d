"""GLSL sources: loading from ``shaders/``, ``#include`` resolution, feature defines, and
a program cache keyed by (files, defines).

Include rules: ``#include "common/x.glsl"`` is resolved against the shader root, each file
is inlined at most once per program (include guards are still written in the files, for
readers), circular includes are an error, and ``#line`` directives keep compiler messages
pointing at real line numbers (the file is named in a ``// --- start of`` marker).

Defines: every switch a shader accepts is declared in its files as
``#ifndef NAME / #define NAME default / #endif``; the loader writes the chosen values
right after ``#version`` and refuses names no included file declares. The cache adds the
context's own switches (``context_defines``, probed by ``capabilities``) to every program
that declares them.
"""

from __future__ import annotations

import re
from pathlib import Path

_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$')
_DECLARED = re.compile(r"^\s*#ifndef\s+([A-Z_][A-Z0-9_]*)\s*$", re.M)


def shader_root() -> Path:
    """``shaders/`` beside the package in a source checkout, ``dvr_gl/shaders`` in a wheel."""
    here = Path(__file__).resolve().parent.parent
    for candidate in (here / "shaders", here.parent / "shaders"):
        if (candidate / "common").is_dir():
            return candidate
    raise FileNotFoundError(f"dvr_gl shader folder not found next to {here}")


class ShaderSourceError(ValueError):
    pass


def resolve_includes(name: str, root: Path | None = None, _stack=None, _seen=None) -> str:
    """The text of shader ``name`` with its includes inlined (each file once)."""
    root = root or shader_root()
    stack = _stack if _stack is not None else []
    seen = _seen if _seen is not None else set()
    if name in stack:
        raise ShaderSourceError("circular #include: " + " -> ".join(stack + [name]))
    path = root / name
    if not path.is_file():
        raise ShaderSourceError(f"shader file {name!r} not found under {root}")
    seen.add(name)
    stack.append(name)
    out = [f"// --- start of \"{name}\" ---"] if len(stack) > 1 else []
    lines = path.read_text().splitlines()
    for lineno, line in enumerate(lines, start=1):
        m = _INCLUDE.match(line)
        if not m:
            out.append(line)
            continue
        child = m.group(1)
        if child in stack:
            raise ShaderSourceError("circular #include: " + " -> ".join(stack + [child]))
        if child not in seen:
            out.append(resolve_includes(child, root, stack, seen))
            if lineno < len(lines):     # (a #line with no line after it is an error on some GPUs)
                out.append(f"#line {lineno + 1}")
    if len(stack) > 1:
        out.append(f"// --- end of \"{name}\" ---")
    stack.pop()
    return "\n".join(out)


def resolve_text(text: str, root: Path | None = None) -> str:
    """Like :func:`resolve_includes` for shader text that is not in a file (the shader
    unit-test harness builds its programs this way)."""
    root = root or shader_root()
    out, seen = [], set()
    for lineno, line in enumerate(text.splitlines(), start=1):
        m = _INCLUDE.match(line)
        if m is None:
            out.append(line)
        elif m.group(1) not in seen:
            out.append(resolve_includes(m.group(1), root, ["<text>"], seen))
            out.append(f"#line {lineno + 1}")
    return "\n".join(out)


def declared_switches(source: str) -> set:
    return set(_DECLARED.findall(source))


def apply_defines(source: str, defines: dict) -> str:
    """Insert ``#define NAME value`` lines after ``#version``; unknown names raise."""
    lines = source.split("\n")
    at = next((i for i, line in enumerate(lines) if line.startswith("#version")), None)
    if at is None:
        raise ShaderSourceError("a shader needs a #version line")
    known = declared_switches(source)
    unknown = sorted(set(defines) - known)
    if unknown:
        raise ShaderSourceError(f"unknown shader switches {unknown}; this shader declares {sorted(known)}")
    header = [f"#define {k} {int(v) if isinstance(v, bool) else v}" for k, v in sorted(defines.items())]
    return "\n".join(lines[:at + 1] + header + [f"#line {at + 2}"] + lines[at + 1:])


def build_source(name: str, defines: dict | None = None) -> str:
    return apply_defines(resolve_includes(name), defines or {})


class ProgramCache:
    """Compiled programs per context, keyed by the shader files and the define set.
    ``probe(ctx)`` gives the context's own switches (``capabilities.context_defines``),
    asked once, on first use."""

    def __init__(self, ctx, probe):
        self.ctx = ctx
        self._probe = probe
        self._programs = {}
        self._context_defines = None
        self.sources = {}  # key -> (vertex source, fragment source[, geometry]); compute: (None, source)

    @property
    def context_defines(self):
        """Switches that follow from the context (``probe``), added to every program
        that declares them."""
        if self._context_defines is None:
            self._context_defines = dict(self._probe(self.ctx))
        return self._context_defines

    def get(self, vertex: str, fragment: str, defines: dict | None = None, geometry: str | None = None):
        defines = dict(defines or {})
        key = (vertex, fragment, tuple(sorted(defines.items()))) + ((geometry,) if geometry else ())
        prog = self._programs.get(key)
        if prog is None:
            defines = {**_only_declared(fragment, self.context_defines), **defines}
            vs = build_source(vertex, _only_declared(vertex, defines))
            fs = build_source(fragment, defines)
            gs = None if geometry is None else build_source(geometry, _only_declared(geometry, defines))
            prog = self.ctx.program(vertex_shader=vs, fragment_shader=fs, geometry_shader=gs)
            self._programs[key] = prog
            self.sources[key] = (vs, fs) if gs is None else (vs, fs, gs)
        return prog

    def compute(self, fragment: str, defines: dict | None = None):
        """The per-pixel fragment shader ``fragment`` built as a compute shader
        (``COMPUTE_PIXELS``, common/pixel_stage.glsl: one invocation per target pixel, 8x8
        a group), GLSL 4.30; a :class:`ComputeProgram`."""
        defines = dict(defines or {}, COMPUTE_PIXELS=1)
        key = ("compute", fragment, tuple(sorted(defines.items())))
        prog = self._programs.get(key)
        if prog is None:
            defines = {**_only_declared(fragment, self.context_defines), **defines}
            source, found = re.subn(r"^#version 330 core$", "#version 430 core", build_source(fragment, defines),
                                    count=1, flags=re.M)
            if not found:
                raise ShaderSourceError(f"{fragment}: a per-pixel shader for the compute stage is "
                                        f"'#version 330 core'")
            prog = ComputeProgram(self.ctx.compute_shader(source))
            self._programs[key] = prog
            self.sources[key] = (None, source)     # (no vertex stage; the per-pixel shader's source)
        return prog

    def release(self):
        for prog in self._programs.values():
            prog.release()
        self._programs.clear()


class ComputeProgram:
    """A compute shader with a program's lookups (``name in prog``, ``prog[name]``,
    ``prog.get(name, default)``), so that the techniques bind it as they bind a fragment
    program."""

    def __init__(self, shader):
        self.shader = shader

    def __contains__(self, name):
        return name in self.shader._members

    def __iter__(self):
        return iter(self.shader._members)

    def __getitem__(self, name):
        return self.shader[name]

    def get(self, name, default):
        return self.shader._members.get(name, default)

    def run(self, groups_x, groups_y):
        self.shader.run(groups_x, groups_y, 1)

    def release(self):
        self.shader.release()


def _only_declared(name, defines):
    known = declared_switches(resolve_includes(name))
    return {k: v for k, v in defines.items() if k in known}
