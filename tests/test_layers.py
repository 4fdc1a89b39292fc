"""The layers of the tree (docs/architecture.md, "How it is built"), checked on every import statement,
at module level or inside functions:

    swarm.contracts   scenario, laws, observation, frames, wire, brain_config, transport: imports none of the others
    world             physics, sensors, the engine, the world process: world + contracts
    agents            laws, selection, the brain, the agent process: agents + contracts
    swarm (the rest)  the shells and tools (sim, launcher, CLI, plots, study): anything

A law named in a scenario is imported by name at run time (swarm/contracts/laws.py), not
by an import statement, so it is no arrow.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
ALLOWED = {
    "contracts": {"contracts"},
    "world": {"world", "contracts"},
    "agents": {"agents", "contracts"},
    "top": {"top", "world", "agents", "contracts"},
}


def layer_of_module(name: str) -> str | None:
    if name == "swarm.contracts" or name.startswith("swarm.contracts."):
        return "contracts"
    head = name.split(".")[0]
    return {"world": "world", "agents": "agents", "swarm": "top"}.get(head)


def layer_of_file(path: Path) -> str:
    rel = path.relative_to(ROOT).with_suffix("")
    return layer_of_module(".".join(rel.parts))


def imports_of(path: Path) -> list[tuple[int, str]]:
    """(line, module) for every import in the file; `from swarm import x` counts as swarm.x."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
            found += [(node.lineno, f"{node.module}.{a.name}") for a in node.names]
    return found


def project_files() -> list[Path]:
    return sorted(p for d in ("swarm", "world", "agents") for p in (ROOT / d).rglob("*.py"))


@pytest.mark.parametrize("path", project_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_follow_the_layers(path):
    here = layer_of_file(path)
    bad = []
    for line, mod in imports_of(path):
        there = layer_of_module(mod)
        if there is not None and there not in ALLOWED[here]:
            bad.append(f"{path.relative_to(ROOT)}:{line} ({here}) imports {mod} ({there})")
    assert not bad, "\n".join(bad)


def folder_graph() -> dict[tuple[str, str], int]:
    """Import statements between layers (the README's picture, counted)."""
    edges: dict[tuple[str, str], int] = {}
    for path in project_files():
        here = layer_of_file(path)
        for _, mod in imports_of(path):
            there = layer_of_module(mod)
            if there is not None and there != here:
                edges[(here, there)] = edges.get((here, there), 0) + 1
    return edges


def test_no_arrow_between_world_and_agents_and_none_up_from_the_contracts():
    edges = folder_graph()
    print("\nimports between layers:", {f"{a} -> {b}": n for (a, b), n in sorted(edges.items())})
    assert ("world", "agents") not in edges and ("agents", "world") not in edges
    assert not [e for e in edges if e[0] == "contracts"]


def test_the_checker_sees_imports_inside_functions(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("def f():\n    from agents.brain import AgentBrain\n    import world.core\n")
    assert {m for _, m in imports_of(p)} >= {"agents.brain", "agents.brain.AgentBrain", "world.core"}
