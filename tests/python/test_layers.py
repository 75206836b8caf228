"""The Python layers import downwards only: gen/lib (the library: bus load, the atomic writer,
the TOML reader, output folders, paths) below gen/ and host_sim/, which sit below tools/. Imports are read with
ast, so a lazy import inside a function counts as much as one at the top of a module."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import pytest

from gen.lib.paths import REPO


def imported_modules(path: Path) -> set[str]:
    """Every module `path` imports (absolute names; a relative import is resolved in its package)."""
    package = ".".join(path.relative_to(REPO).with_suffix("").parts[:-1])
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(parts + ([base] if base else []))
            out.add(base)
            out.update(f"{base}.{a.name}" for a in node.names)  # `from gen import lib`
    return out


def _modules(folder: str) -> list[Path]:
    return sorted(p for p in (REPO / folder).rglob("*.py") if "__pycache__" not in p.parts)


def _offenders(folder: str, forbidden: tuple[str, ...]) -> list[str]:
    bad = []
    for path in _modules(folder):
        for mod in sorted(imported_modules(path)):
            if any(mod == f or mod.startswith(f + ".") for f in forbidden):
                bad.append(f"{path.relative_to(REPO)} imports {mod}")
    return bad


@pytest.mark.parametrize("folder", ["gen", "host_sim"])
def test_no_module_in_gen_or_host_sim_imports_tools(folder: str) -> None:
    assert _modules(folder), folder
    assert _offenders(folder, ("tools",)) == []


def test_the_library_imports_nothing_above_it() -> None:
    above = ("tools", "host_sim") + tuple(f"gen.{p.stem}" for p in (REPO / "gen").iterdir()
                                          if p.stem not in ("lib", "__init__", "__pycache__"))
    assert _offenders("gen/lib", above) == []


def test_the_checker_sees_lazy_and_relative_imports(tmp_path: Path) -> None:
    """The test above would pass on a checker that sees nothing: it finds both kinds."""
    mod = REPO / "host_sim" / "_layers_probe.py"
    try:
        mod.write_text("def f():\n    from tools import busload\n    from .. import tools as t\n")
        assert _offenders("host_sim", ("tools",)) == ["host_sim/_layers_probe.py imports tools",
                                                      "host_sim/_layers_probe.py imports tools.busload"]
    finally:
        mod.unlink()


def test_gen_imports_nothing_of_host_sim() -> None:
    assert _offenders("gen", ("host_sim",)) == []


def _module_name(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


@functools.cache
def import_graph() -> dict[str, set[str]]:
    """Each module of gen/, host_sim/ and tools/ (a package is its __init__.py) -> the modules of
    those three it imports. An imported name counts as the longest module it names:
    `from tools.run.hil import provenance` is tools.run.hil, `from tools.study import bandwidth` is
    tools.study and tools.study.bandwidth (imported_modules gives both names)."""
    files = {_module_name(p): p for folder in ("gen", "host_sim", "tools") for p in _modules(folder)}

    def module_of(name: str) -> str | None:
        parts = name.split(".")
        return next((m for m in (".".join(parts[:i]) for i in range(len(parts), 0, -1)) if m in files), None)

    return {m: {t for t in map(module_of, imported_modules(p)) if t is not None and t != m}
            for m, p in files.items()}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Every import circle: per strongly connected component of more than one module (Tarjan), the
    shortest way round it from its first module, e.g. [a, b, c, a]."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    components: list[set[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = {stack.pop()}
            while v not in component:
                component.add(stack.pop())
            if len(component) > 1:
                components.append(component)

    for v in sorted(graph):
        if v not in index:
            visit(v)
    out = []
    for component in components:
        start = min(component)
        paths = {start: [start]}  # breadth first inside the component, back to start
        queue = [start]
        while queue:
            v = queue.pop(0)
            if start in graph[v]:
                out.append(paths[v] + [start])
                break
            for w in sorted(graph[v] & component):
                if w not in paths:
                    paths[w] = paths[v] + [w]
                    queue.append(w)
    return sorted(out)


def test_no_import_circle_in_gen_host_sim_or_tools() -> None:
    graph = import_graph()
    assert {"gen.lib.paths", "host_sim.launch", "tools.cli"} <= graph.keys()
    assert [" -> ".join(c) for c in circles(graph)] == []


def test_the_circle_finder_names_each_circle() -> None:
    """The test above would pass on a finder that finds nothing: a circle, a longer one through
    it, and a module that only leads into a circle."""
    graph = {"a": {"b"}, "b": {"a", "c"}, "c": {"a"}, "d": {"a"}, "e": {"f"}, "f": {"e"}, "g": set()}
    assert circles(graph) == [["a", "b", "a"], ["e", "f", "e"]]
    assert circles({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == [["a", "b", "c", "a"]]


# tools/ by job, lowest first: a module imports only modules of its own level or below (and gen,
# host_sim). The loose helpers sit lowest; tools/vcan.py (which runs the VM, for tools/run/hil.py)
# between vm and run; the CLI (tools/cli.py, tools/commands/) above them all.
TOOL_LAYERS = (("errors", "methods", "busload"), ("build",), ("vm",), ("vcan",), ("run",), ("identify",), ("study",), ("bench",),
               ("cli", "commands"))


def _level(module: str) -> int | None:
    """The level of a module of tools/ (None: tools/__init__.py, or a part no level names)."""
    parts = module.split(".")
    if parts[0] != "tools" or len(parts) == 1:
        return None
    return next((i for i, names in enumerate(TOOL_LAYERS) if parts[1] in names), None)


def test_every_part_of_tools_has_a_level() -> None:
    parts = {m.split(".")[1] for m in import_graph() if m.startswith("tools.")}
    assert sorted(p for p in parts if _level(f"tools.{p}") is None) == []


@pytest.mark.parametrize("level", range(len(TOOL_LAYERS)), ids=["+".join(names) for names in TOOL_LAYERS])
def test_each_tools_package_imports_only_the_packages_below_it(level: int) -> None:
    graph = import_graph()
    assert any(_level(m) == level for m in graph), TOOL_LAYERS[level]
    upward = [f"{m} imports {t}" for m in sorted(graph) if _level(m) == level
              for t in sorted(graph[m]) if (_level(t) or 0) > level]
    assert upward == []


def test_tools_is_split_by_job() -> None:
    """No module of a job's package lies loose in tools/ (only the CLI and a few shared helpers do)."""
    loose = sorted(p.name for p in (REPO / "tools").glob("*.py"))
    assert loose == ["__init__.py", "busload.py", "cli.py", "errors.py", "methods.py", "vcan.py"], loose


# A function longer than this is split into named steps that each do one job.
LONGEST_FUNCTION = 80
# The only longer ones, each with its reason.
LONG_FUNCTION_EXEMPT = {
    # a C header as one f-string template: its lines are the header's, not steps
    "gen/synth/emit.py:fixed_header",
}


def long_functions(path: Path) -> list[tuple[str, int]]:
    """Every function (or method) of `path` longer than LONGEST_FUNCTION lines, with its length."""
    return [(node.name, node.end_lineno - node.lineno + 1)
            for node in ast.walk(ast.parse(path.read_text(), str(path)))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno is not None
            and node.end_lineno - node.lineno + 1 > LONGEST_FUNCTION]


def test_no_function_in_gen_host_sim_or_tools_is_longer_than_80_lines() -> None:
    long = [f"{path.relative_to(REPO)}:{name} ({n} lines)" for folder in ("gen", "host_sim", "tools")
            for path in _modules(folder) for name, n in long_functions(path)
            if f"{path.relative_to(REPO)}:{name}" not in LONG_FUNCTION_EXEMPT]
    assert long == []


def test_the_length_check_sees_a_long_function(tmp_path: Path) -> None:
    """The test above would pass on a checker that measures nothing: an 81-line function is found,
    an 80-line one is not."""
    body = "    x = 0\n" * (LONGEST_FUNCTION - 2)
    probe = tmp_path / "probe.py"
    probe.write_text(f"def short():\n{body}    return x\n\ndef long():\n{body}    x += 1\n    return x\n")
    assert long_functions(probe) == [("long", LONGEST_FUNCTION + 1)]


def test_each_exempt_long_function_exists_and_is_long() -> None:
    for entry in sorted(LONG_FUNCTION_EXEMPT):
        path, name = entry.split(":")
        assert name in dict(long_functions(REPO / path)), f"{entry} is no longer long: drop its exemption"
