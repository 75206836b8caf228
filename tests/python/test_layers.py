"""The Python layers import downwards only: gen/lib (the library: bus load, the atomic writer,
the TOML reader, output folders, paths) below gen/ and host_sim/, which sit below tools/. Imports are read with
ast, so a lazy import inside a function counts as much as one at the top of a module."""

from __future__ import annotations

import ast
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


# tools/ by job, lowest first: a package imports only those below it (and gen, host_sim); the CLI
# (tools/cli.py, tools/commands/) sits above them all.
TOOL_LAYERS = ("build", "run", "identify", "study", "bench")


@pytest.mark.parametrize("level", range(len(TOOL_LAYERS)))
def test_each_tools_package_imports_only_the_packages_below_it(level: int) -> None:
    above = tuple(f"tools.{p}" for p in TOOL_LAYERS[level + 1:]) + ("tools.cli",)
    assert _offenders(f"tools/{TOOL_LAYERS[level]}", above) == []


def test_tools_is_split_by_job() -> None:
    """No module of a job's package lies loose in tools/ (only the CLI and a few shared helpers do)."""
    loose = sorted(p.name for p in (REPO / "tools").glob("*.py"))
    assert loose == ["__init__.py", "busload.py", "cli.py", "methods.py", "vcan.py"], loose
