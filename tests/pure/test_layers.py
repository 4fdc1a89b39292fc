"""The layers of the tree (docs: design/architecture.md, "Layers"), checked on every import
statement, at module level or inside functions:

    contracts  scenario, laws, wire, transport, vocabulary, errors...: imports none of the others
    world      physics, sensors, the engine, the world process (swarm.world, the world/ folder)
    agents     laws, selection, the brain, the agent process (swarm.agents, the agents/ folder)
    runtime    launcher, supervision, process groups, fork server client, agent hosts
    offline    swarm sim, the batch engine, a run's output directory, CSV export
    plots      a run's figures
    live       a live run seen from a terminal: client, data, control, views, watch, Foxglove
    ros2       the rmw_zenoh protocol (keys, liveliness tokens, attachments, CDR): ROS 2 without ROS
    robots     real robots: the world's plant made of ROS 2 robots, the robots file, a simulated fleet
    study      batch studies
    api        the Python API (`import swarm`)
    env        a PettingZoo environment over the in-process engine (learning-based laws)
    testing    a law's unit tests: frames and observations from keywords, a fake world link (no zenoh)
    cli        the command line

A package may import only the packages `MAY_IMPORT` lists for it; no module may be part of an
import cycle. A law named in a scenario is imported by name at run time
(swarm/contracts/laws.py), not by an import statement, so it is no arrow.
"""

from __future__ import annotations

import ast
import functools
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BELOW_THE_SHELLS = {"contracts", "world", "agents"}
MAY_IMPORT = {
    "contracts": {"contracts"},
    "world": {"world", "contracts"},
    "agents": {"agents", "contracts"},
    "runtime": {"runtime", "contracts", "world"},
    "offline": {"offline", "ros2"} | BELOW_THE_SHELLS,
    "plots": {"plots", "offline"} | BELOW_THE_SHELLS,
    "live": {"live", "runtime"} | BELOW_THE_SHELLS,
    "study": {"study", "offline"} | BELOW_THE_SHELLS,
    "ros2": {"ros2", "contracts"},  # the rmw_zenoh protocol: keys, tokens, attachments, CDR
    "robots": {"robots", "ros2", "runtime"} | BELOW_THE_SHELLS,
    # the PettingZoo environment over the in-process engine; its episode's results are the API's
    # `Results` (what swarm.simulate returns), so it sits above swarm.api
    "env": {"env", "offline", "api"} | BELOW_THE_SHELLS,
    # a law author's test kit: the agent's brain, the wire's codecs, the world's kinematics and
    # sensors; no zenoh (tests/pure/test_testing_kit.py)
    "testing": {"testing"} | BELOW_THE_SHELLS,
    "api": {"api", "runtime", "offline", "plots", "live", "robots"} | BELOW_THE_SHELLS,
    "cli": {"cli", "root", "api", "runtime", "offline", "plots", "live", "study", "robots", "ros2", "env"}
    | BELOW_THE_SHELLS,
    "root": {"root", "cli", "api", "contracts", "env", "study"},  # swarm/__init__.py (its exports), swarm/__main__.py
}
PACKAGES = set(MAY_IMPORT) - {"root"}
FOLDERS = {"swarm": "swarm", "agents": "swarm.agents", "world": "swarm.world"}  # folder -> import name


def module_of_file(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    parts[0] = FOLDERS[parts[0]]
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def package_of(module: str) -> str | None:
    """The layer of a module of this project (None for anything else)."""
    parts = module.split(".")
    if parts[0] != "swarm":
        return None
    return parts[1] if len(parts) > 1 and parts[1] in PACKAGES else "root"


@functools.cache
def import_statements(path: Path) -> tuple[tuple[ast.Import | ast.ImportFrom, bool], ...]:
    """(import statement, inside a function) of a file, parsed once for every check of this
    module (the statements alone are kept: whole trees kept alive made the collector slow)."""
    tree = ast.parse(path.read_text(), str(path))
    return tuple((s, inside) for s, inside in statements(tree) if isinstance(s, (ast.Import, ast.ImportFrom)))


def statements(node: ast.AST, in_function: bool = False) -> Iterator[tuple[ast.AST, bool]]:
    """(statement, inside a function) for every statement under `node`, through the bodies of
    compound statements only: an import is a statement, so no expression needs a visit (a
    walk of every node took seconds over the project and its tests)."""
    for field in ("body", "orelse", "finalbody", "handlers", "cases"):
        for child in getattr(node, field, ()):
            yield child, in_function
            yield from statements(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)))


@functools.cache
def imports_of(path: Path, here: str | None = None) -> tuple[tuple[int, str, bool], ...]:
    """(line, module, inside a function) for every import in the file (module `here`, by
    default the file's own); `from swarm.x import y` counts as swarm.x.y when swarm/x/y is a
    module, and relative imports are resolved."""
    here = here or module_of_file(path)
    found = []

    for child, in_function in import_statements(path):
        if isinstance(child, ast.Import):
            found.extend((child.lineno, a.name, in_function) for a in child.names)
        elif isinstance(child, ast.ImportFrom):
            if child.level:
                base = here.split(".")[: len(here.split(".")) - child.level + (path.name == "__init__.py")]
                module = ".".join(base + ([child.module] if child.module else []))
            else:
                module = child.module or ""
            found.append((child.lineno, module, in_function))
            found.extend(
                (child.lineno, f"{module}.{a.name}", in_function)
                for a in child.names
                if f"{module}.{a.name}" in MODULES
            )
    return tuple(found)


def project_files() -> list[Path]:
    return sorted(p for d in FOLDERS for p in (ROOT / d).rglob("*.py"))


MODULES = {module_of_file(p) for p in project_files()}


@pytest.mark.parametrize("path", project_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_follow_the_layers(path):
    here = package_of(module_of_file(path))
    bad = [
        f"{path.relative_to(ROOT)}:{line} ({here}) imports {mod} ({package_of(mod)})"
        for line, mod, _ in imports_of(path)
        if package_of(mod) is not None and package_of(mod) not in MAY_IMPORT[here]
    ]
    assert not bad, "\n".join(bad)


def test_no_project_module_imports_the_folders_by_their_folder_names():
    """`agents` and `world` are folders of the repository, installed as swarm.agents and
    swarm.world: importing them by the folder name works only from the repository's root."""
    bad = [
        f"{p.relative_to(ROOT)}:{line} imports {mod}"
        for p in project_files() + sorted((ROOT / "tests").rglob("*.py"))
        for line, mod, _ in imports_of_any(p)
        if mod.split(".")[0] in ("agents", "world")
    ]
    assert not bad, "\n".join(bad)


def imports_of_any(path: Path) -> list[tuple[int, str, bool]]:
    """imports_of for files outside the packages too (tests): absolute imports only."""
    out = []
    for node, _ in import_statements(path):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name, False) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            out.append((node.lineno, node.module, False))
    return out


def module_graph() -> dict[str, set[str]]:
    """Module -> the project modules it imports (at module level or inside functions)."""
    graph: dict[str, set[str]] = {}
    for p in project_files():
        here = module_of_file(p)
        deps = graph.setdefault(here, set())
        for _, mod, _ in imports_of(p):
            while mod and mod not in MODULES:  # `from swarm.x import name`: the module swarm.x
                mod = mod.rpartition(".")[0]
            if mod and mod != here and not here.startswith(mod + "."):  # a package's own __init__ is no cycle
                deps.add(mod)
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph.get(v, ()):
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
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return out


def test_no_import_cycle():
    found = cycles(module_graph())
    assert not found, "import cycles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_the_cycle_finder_finds_one():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def package_graph() -> dict[tuple[str, str], int]:
    """Import statements between packages (the picture in the architecture page, counted)."""
    edges: dict[tuple[str, str], int] = {}
    for path in project_files():
        here = package_of(module_of_file(path))
        for _, mod, _ in imports_of(path):
            there = package_of(mod)
            if there is not None and there != here:
                edges[(here, there)] = edges.get((here, there), 0) + 1
    return edges


def test_no_arrow_between_world_and_agents_and_none_up_from_the_contracts():
    edges = package_graph()
    print("\nimports between packages:", {f"{a} -> {b}": n for (a, b), n in sorted(edges.items())})
    assert ("world", "agents") not in edges and ("agents", "world") not in edges
    assert not [e for e in edges if e[0] == "contracts"]


def test_the_checker_sees_imports_inside_functions(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("import json\ndef f():\n    from swarm.agents.brain import AgentBrain\n    import swarm.world.core\n")
    found = {(m, inside) for _, m, inside in imports_of(p, "swarm.contracts.m")}
    assert {("json", False), ("swarm.agents.brain", True), ("swarm.world.core", True)} <= found
    assert package_of("swarm.agents.brain") not in MAY_IMPORT["contracts"]


def unexplained_lazy_imports(path: Path, here: str | None = None) -> list[int]:
    """Lines of imports inside functions without a `lazy:` reason: in a comment at the end of
    the import's first line, or in the comment lines right above its block of imports."""
    lines = path.read_text().splitlines()

    def explained(lineno: int) -> bool:
        if "lazy:" in lines[lineno - 1]:
            return True
        i = lineno - 2
        while i >= 0:
            s = lines[i].strip()
            if s.startswith("#"):
                if "lazy:" in s:
                    return True
            elif not (s.startswith(("import ", "from ", ")")) or (s and lines[i].rstrip().endswith(","))):
                return False
            i -= 1
        return False

    return sorted({line for line, _, inside in imports_of(path, here) if inside and not explained(line)})


def test_imports_inside_functions_say_why():
    """An import inside a function is there for start-up time (the CLI, agent processes), an
    optional heavy dependency or a crash path, and says so: `# lazy: <reason>`."""
    bad = [f"{p.relative_to(ROOT)}:{line}" for p in project_files() for line in unexplained_lazy_imports(p)]
    assert not bad, "imports inside functions without a `# lazy:` reason:\n" + "\n".join(bad)


def test_the_lazy_check_finds_an_unexplained_import(tmp_path):
    probe = tmp_path / "probe.py"
    probe.write_text(
        "import sys\n\ndef f():\n    # lazy: numpy costs 0.1 s\n    import numpy\n    import json\n\n"
        "def g():\n    x = 1\n    import os\n    from json import dumps  # lazy: a reason at the end\n"
    )
    assert unexplained_lazy_imports(probe, "swarm.contracts.probe") == [10]
