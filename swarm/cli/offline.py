"""Commands that need no running swarm (`swarm check / schema`; `plot / export` live in
swarm/cli/plot.py). The scenario argument and reading it are swarm/cli/options.py's."""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

import typer

from swarm.cli.options import ScenarioArg, read_scenario
from swarm.contracts.graph import analyse

if TYPE_CHECKING:  # the scenario model (pydantic) is imported by the commands that read one:
    from swarm.contracts.scenario import Scenario  # live commands start without it (~0.13 s)


def check(scenario: ScenarioArg) -> None:
    """Validate a scenario file and print a short summary of it.

    Example: swarm check scenarios/case2.toml
    """
    s = read_scenario(scenario)
    r = s.run
    typer.echo(f"{scenario}: ok - {s.name or scenario.stem}")
    typer.echo(
        f"  run: dt={r.dt} s, duration={r.duration} s ({r.ticks} ticks), clock={r.clock}, "
        f"seed={r.seed}, on_dropout={r.on_dropout}"
    )
    typer.echo(f"  added agents: up to {len(s.added_id_range)} ({s.added_ids_text()})")
    typer.echo(f"  target: ({s.target.x}, {s.target.y}) m; gains: c1={s.gains.c1}, c2={s.gains.c2}")
    # lazy: loaded with the scenario by now; `swarm --help` starts without it
    from swarm.contracts.laws import follower_law_name

    follower = follower_law_name(s.gains.law, s.law.follower)[1]
    params = ", ".join(f"{k}={v:g}" for k, v in s.law.params.items())
    typer.echo(f"  laws: follower={follower}, leader={s.law.leader}" + (f"; params: {params}" if params else ""))
    sens = s.sensing
    typer.echo(
        f"  sensing: range={'unlimited' if sens.range is None else f'{sens.range} m'}, "
        f"fov={'all round' if sens.fov is None else f'{sens.fov} rad'}, "
        f"selection={sens.selection}, hysteresis={sens.hysteresis}"
    )
    if s.safety is not None:
        sf = s.safety
        arena = "none" if sf.corners is None else " ".join(f"({x:g}, {y:g})" for x, y in sf.corners)
        typer.echo(
            f"  safety: {'filter' if sf.enabled else 'measured only (enabled = false)'}, radius={sf.radius:g} m, "
            f"lookahead={sf.lookahead_m:g} m, gamma={sf.gamma:g}/s, speed {'may' if sf.speed else 'may not'} "
            f"change, arena: {arena}"
        )
        unbounded = [a.id for a in s.agents if a.max_turn_rate is None]
        if unbounded and sf.enabled:
            typer.echo(
                f"  warning: agents {', '.join(map(str, unbounded))} have no max_turn_rate: the safety filter's "
                "turn rates for them are unbounded"
            )
    for a in s.agents:
        extra = (
            f"R={a.orbit_radius} m {a.direction}"
            if a.role == "leader"
            else f"follow={a.follow}"
            if a.follow is not None
            else f"out-neighbour: {sens.selection}"
        )
        lim = "" if a.max_turn_rate is None else f", |u|<={a.max_turn_rate} rad/s"
        typer.echo(
            f"  agent {a.id:>3} {a.role:<8} at ({a.x:g}, {a.y:g}) heading {a.heading:g} rad, "
            f"{a.speed:g} m/s, {extra}{lim}"
        )
    for f in s.faults:
        who = "every agent" if f.agent is None else f"agent {f.agent}"
        more = ", ".join(
            f"{k}={v}"
            for k, v in (("duration", f.duration), ("probability", f.probability), ("delay", f.delay), ("std", f.std))
            if v is not None
        )
        typer.echo(f"  fault at {f.at:g} s: {f.kind} {who}" + (f" ({more})" if more else ""))
    _warn_nearest_graph(s)
    for line in arena_warnings(s):
        typer.secho(f"  warning: {line}", fg=typer.colors.YELLOW)


def arena_warnings(s: Scenario) -> list[str]:
    """What in a scenario fights its [safety] arena: an agent starting within the lookahead of a
    wall, and a leader's orbit (radius about the target, plus the lookahead) that
    does not fit: the wall barriers would keep turning that leader off its orbit."""
    sf = s.safety
    if sf is None or sf.corners is None:
        return []
    out = []
    margin = sf.lookahead_m
    for a in s.agents:
        c = sf.clearance(a.x, a.y)  # outside: refused by the scenario model already
        if 0 <= c < margin:
            out.append(f"agent {a.id} starts {c:.3g} m from a wall, within the lookahead ({margin:g} m)")
    room = sf.clearance(s.target.x, s.target.y)
    for a in s.agents:
        if a.role == "leader" and a.orbit_radius is not None and a.orbit_radius + margin > room:
            out.append(
                f"leader {a.id}'s orbit (R = {a.orbit_radius:g} m about the target) does not fit in the arena: "
                f"the nearest wall is {room:.3g} m from the target, the orbit needs R + lookahead = "
                f"{a.orbit_radius + margin:.3g} m"
            )
    return out


def _warn_nearest_graph(s: Scenario) -> None:
    """Warn (exit 0) when the paper's nearest choice at t = 0 breaks Assumption 1."""
    # lazy: the world's core (numpy, the scenario model: ~0.12 s) and the agents' selection, not for `swarm --help`
    from swarm.agents.selection import nearest
    from swarm.world.core import WorldCore

    leaders = {a.id for a in s.agents if a.role == "leader"}
    out = {
        aid: (None if aid in leaders else (c.id if (c := nearest(f.contacts)) else None))
        for aid, f in WorldCore(s).frames().items()
    }
    g = analyse(out, leaders)
    problems = [f"follower-only cycle {' -> '.join(map(str, c + c[:1]))}" for c in g["cycles"]]
    lone = [i for i in g["unrooted"] if not any(i in c for c in g["cycles"])]
    if lone:
        problems.append(f"no path to a leader from {', '.join(map(str, lone))}")
    if not problems:
        return
    edges = ", ".join(f"{i}->{j}" for i, j in g["edges"])
    cure = {
        "nearest": "this run keeps re-choosing the nearest agent and may never converge; "
        'selection = "sticky" (the default) keeps every follower rooted',
        "sticky": 'selection = "sticky" roots these followers on the nearest agent that has a path, '
        "and those that sense none shadow or search until one is in reach",
        "rooted": 'selection = "rooted" roots these followers on the nearest agent that has a path',
        "fixed": "this scenario pins its graph with `follow`",
    }[s.sensing.selection]
    typer.secho(
        f"  warning: nearest choice at t = 0 ({edges}) breaks the paper's Assumption 1: {'; '.join(problems)}. {cure}.",
        fg=typer.colors.YELLOW,
    )


def schema() -> None:
    """Print the JSON Schema of scenario files (for editors and tools).

    Example: swarm schema > scenario.schema.json
    """
    from swarm.contracts.scenario import scenario_json_schema  # lazy: pydantic (~90 ms), not for `swarm --help`

    typer.echo(json.dumps(scenario_json_schema(), indent=2))


def register(app: typer.Typer) -> None:
    """Add the offline commands to the main app."""
    app.command("check")(check)
    app.command("schema")(schema)
