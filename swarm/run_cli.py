"""Commands that run a scenario (`swarm sim / world / agent`, and `swarm up` in
swarm/up_cli.py): the options they share are declared once, below, as `Annotated` types."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.contracts.lifeline import LAUNCHER_PID_ENV
from swarm.contracts.wire import MAX_AGENT_ID
from swarm.live_cli import CredentialsOpt, TrustLawOpt
from swarm.cli_errors import fail
from swarm.offline_cli import ScenarioArg, read_scenario, render_run_plots


def out_option(help: str):
    return Annotated[Optional[Path], typer.Option("--out", "-o", help=help)]


SimOutOpt = out_option("output directory (default runs/<scenario>-sim-<time>-<random>); one that "
                       "already holds results is refused unless --force")
WorldOutOpt = out_option("where to write the results (default: nowhere); one that already holds "
                         "results is refused unless --force")
ForceOpt = Annotated[bool, typer.Option("--force", help="replace the results already in --out")]
# (no range of typer's: the scenario's own checks say what is wrong with any value, check_duration)
DurationOpt = Annotated[Optional[float], typer.Option(help="simulated seconds (default: the "
                                                      "scenario's run.duration)")]
ClockOpt = Annotated[Optional[str], typer.Option(help="lockstep | realtime (default: the scenario's)")]
TimeScaleOpt = Annotated[float, typer.Option("--time-scale", "--speed", help="realtime clock: simulated "
                                             "seconds per wall second", min=1e-6)]
EndPlotsOpt = Annotated[bool, typer.Option(help="render PNG plots at the end")]
FoxgloveOpt = Annotated[bool, typer.Option("--foxglove", help="serve the run live to the Foxglove app "
                                           "(WebSocket, ws://HOST:PORT; `--foxglove PORT` for another port "
                                           "than 8765; docs/outputs.md, \"Live view in Foxglove\")")]
FoxglovePortOpt = Annotated[int, typer.Option("--foxglove-port", help="--foxglove: the port (`--foxglove PORT` "
                                              "says the same)", min=1, max=65535)]
FoxgloveHostOpt = Annotated[str, typer.Option("--foxglove-host", help="--foxglove: the address to bind "
                                              "(0.0.0.0: every interface, anyone who can reach it sees the run)")]


def default_out(scenario_path: Path, kind: str) -> Path:
    """A new directory under runs/: the time and a random part, so two runs never share one."""
    import secrets

    return Path("runs") / f"{scenario_path.stem}-{kind}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(3)}"


def claim_out(out: Path, force: bool) -> None:
    from swarm.results import OutDirError, claim_out_dir

    try:
        claim_out_dir(out, force)
    except OutDirError as e:
        raise fail(str(e), 2) from None


def check_duration(s, duration: float | None, path: Path) -> None:
    """--duration goes through the scenario's own checks (positive, finite, at least one
    step, a recording that fits in memory): one line naming the option and its value, as
    typer's range errors are said (swarm/cli_errors.py), exit 2."""
    if duration is None:
        return
    from swarm.contracts.scenario import ScenarioError, parse_scenario

    try:
        parse_scenario({**s.model_dump(), "run": {**s.run.model_dump(), "duration": duration}},
                       f"{path} with --duration {duration:g}")
    except ScenarioError as e:
        why = []
        for line in str(e).splitlines()[1:]:
            line = line.strip().removeprefix("run.duration: ")
            why.append(line[len("Input "):] if line.startswith("Input should be ") else line)
        raise fail(f"--duration {duration:g}: {'; '.join(why)} ({path})", 2) from None


def check_runtime_dir() -> None:
    """The runtime dir (sockets, credentials) must be the user's own: one line, exit 2."""
    from swarm.contracts.identities import CredentialsError
    from swarm.contracts.runtime_dir import runtime_dir

    try:
        runtime_dir()
    except CredentialsError as e:
        raise fail(f"swarm: {e}", 2) from None


def check_clock(clock: str | None) -> None:
    if clock is not None and clock not in ("lockstep", "realtime"):
        raise fail(f"--clock must be lockstep or realtime, not {clock!r}", 2)


def check_foxglove(host: str, port: int) -> None:
    """The --foxglove port must be free to bind: one line naming the option, exit 2 (the
    world checks again when it binds, world/live_view.py)."""
    import socket

    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        with socket.socket(infos[0][0], socket.SOCK_STREAM) as so:
            so.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            so.bind(infos[0][4])
    except OSError as e:
        raise fail(f"--foxglove: cannot serve on {host}:{port}: {e.strerror or e}", 2) from None


def _progress_bar(label: str):
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn(label), BarColumn(), TextColumn("{task.completed}/{task.total} ticks"),
                    TimeRemainingColumn(), transient=True, disable=not sys.stderr.isatty())


def print_summary(summary: dict, out: Path) -> None:
    typer.echo(f"converged: {summary['converged']}  ticks: {summary['ticks']}  "
               f"sim time: {summary['sim_time']:.2f} s  selection: {summary.get('selection', '-')}  "
               f"switches: {summary.get('switches', '-')}")
    typer.echo(f"  {'id':>3} {'role':<8} {'out':>4} {'root':>4} {'radius':>9} {'expected':>9} "
               f"{'error %':>8} {'rate':>8} {'settle s':>8} {'switches':>8}")
    for aid, a in summary["agents"].items():
        def f(v, fmt):
            return "-" if v is None else format(v, fmt)
        typer.echo(f"  {aid:>3} {a['role']:<8} {f(a['out_neighbour'], 'd'):>4} {f(a['root'], 'd'):>4} "
                   f"{a['final_radius']:9.3f} {f(a['expected_radius'], '9.3f'):>9} "
                   f"{f(None if a['relative_error'] is None else 100 * a['relative_error'], '8.3f'):>8} "
                   f"{f(a['angular_rate'], '8.4f'):>8} {f(a['settling_time'], '8.2f'):>8} "
                   f"{f(a.get('switches'), 'd'):>8}"
                   + ("" if a["alive"] else "  (dropped)"))
    why = summary.get("not_reproducible") or []
    if summary.get("clock") == "lockstep" and summary.get("reproducible") is False and why:
        more = f" (and {len(why) - 1} more: summary.json, not_reproducible)" if len(why) > 1 else ""
        typer.echo(f"not what lockstep promises (swarm sim would differ): {why[0]}{more}")
    typer.echo(f"results: {out}")


def sim(
    scenario: ScenarioArg,
    out: SimOutOpt = None,
    duration: DurationOpt = None,
    plots: Annotated[bool, typer.Option(help="render PNG plots")] = True,
    force: ForceOpt = False,
    batch: Annotated[bool, typer.Option("--batch", help="step all agents as arrays (the batch engine: the "
                                        "same results, faster for many agents); refuses scenarios with "
                                        "faults or a law of one's own (follower or leader)")] = False,
) -> None:
    """Run a scenario in one process (the reference engine) and write its results.

    Streams recording.mcap into --out as it runs, then writes trajectory.npz, summary.json
    and PNG plots. With --batch the batch engine runs it (summary.json says
    "engine": "sim-batch"; everything else is the same).

    Example: swarm sim scenarios/case2.toml --out runs/case2
    """
    from swarm.api import simulate
    from world.recording import EXIT_NO_SPACE, RecordingError

    s = read_scenario(scenario)
    check_duration(s, duration, scenario)
    if batch:
        from swarm.batch import refusal

        why = refusal(s)
        if why is not None:
            raise fail(f"swarm sim --batch: {scenario}: {why}; run it without --batch", 2)
    out = out or default_out(scenario, "sim")
    total = int(round((duration or s.run.duration) / s.run.dt))
    try:
        with _progress_bar(f"sim {scenario.stem}") as prog:
            task = prog.add_task("sim", total=total)
            results = simulate(s, duration, out, force=force, batch=batch,
                               progress=lambda k, n: prog.update(task, completed=k))
    except RecordingError as e:
        raise fail(f"swarm sim: {e}", EXIT_NO_SPACE) from None
    summary, wall = results.summary.to_dict(), results.summary["wall_time"]
    print_summary(summary, out)
    typer.echo(f"speed: {total * s.run.dt / wall:.1f} simulated s per wall s ({total / wall:.0f} ticks/s)")
    if plots:
        render_run_plots(out)
    crashes = [e for e in summary["events"] if e["kind"] == "crash"]
    if crashes:  # as swarm up: results written, one line, exit 4
        from swarm.api_launch import EXIT_AGENT_FAILED

        e = crashes[0]
        raise fail(f"swarm sim: {len(crashes)} agent(s) failed: agent {e['agent']} at t = {e['time']:g} s: "
                   f"its law raised {e['cause']} (results in {out})", EXIT_AGENT_FAILED)


def world(
    scenario: ScenarioArg,
    listen: Annotated[Optional[str], typer.Option(help="zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7447 "
                                                  "or unixsock-stream/PATH (default: a Unix socket in "
                                                  "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)")] = None,
    run: Annotated[Optional[str], typer.Option(help="run id: the key prefix (default <scenario>-<random>)")] = None,
    out: WorldOutOpt = None,
    duration: Annotated[Optional[float], typer.Option(help="simulated seconds")] = None,
    clock: ClockOpt = None,
    time_scale: TimeScaleOpt = 1.0,
    join_timeout: Annotated[Optional[float], typer.Option(help="give up if not every agent joined "
                                                          "within this many s (default: wait)")] = None,
    plots: EndPlotsOpt = True,
    force: ForceOpt = False,
    foxglove: FoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
) -> None:
    """Run the world of a scenario by hand: the hub, physics, sensors and the recording.

    Agents join with `swarm agent --id N --connect ENDPOINT` from any terminal or machine.
    With --out, the end prints the summary table `swarm up` prints.

    Example: swarm world scenarios/case2.toml --listen tcp/0.0.0.0:7447 --out runs/case2
    """
    from swarm.contracts.transport import default_endpoint
    from swarm.contracts.wire import WireError, check_run_id
    from world.clock import EXIT_DESERTED
    from world.main import run_world
    from world.process import WorldConfig

    s = read_scenario(scenario)
    check_duration(s, duration, scenario)
    check_runtime_dir()
    if not run:
        from swarm.api_launch import new_run_id

        run = new_run_id(scenario)
    try:
        check_run_id(run)
    except WireError as e:
        raise fail(str(e), 2) from None
    clock = clock or s.run.clock
    check_clock(clock)
    listen = listen or default_endpoint(run)
    if foxglove:
        if out is None:
            raise fail("--foxglove needs --out: the live view serves the run's recording as it is written", 2)
        check_foxglove(foxglove_host, foxglove_port)
    if out is not None:
        claim_out(out, force)
    typer.echo(f"run {run} on {listen}; " + (f"results in {out}" if out else "no results kept (no --out)"), err=True)
    code = run_world(WorldConfig(s, run, listen, out, clock, time_scale, duration, join_timeout,
                                 foxglove=(foxglove_host, foxglove_port) if foxglove else None))
    summary = out / "summary.json" if out is not None else None
    # the table `swarm up` prints; not when the launcher runs us (it prints its own, and reads a
    # world's failure from the last line of its log)
    launched = bool(os.environ.get(LAUNCHER_PID_ENV))
    if summary is not None and not launched and code in (0, 130, 143, EXIT_DESERTED) and summary.exists():
        import json

        print_summary(json.loads(summary.read_text()), out)  # the table `swarm up` prints
    if plots and out is not None and code in (0, 130, 143) and (out / "trajectory.npz").exists():
        render_run_plots(out)
    raise typer.Exit(code)


def agent(
    id: Annotated[int, typer.Option("--id", help="the agent's id in the scenario", min=0, max=MAX_AGENT_ID)],
    connect: Annotated[str, typer.Option(help="the world's endpoint, e.g. tcp/HOST:7447 or "
                                         "unixsock-stream/PATH")],
    run: Annotated[Optional[str], typer.Option(help="run id (default: the only run on the endpoint)")] = None,
    wait_world: Annotated[bool, typer.Option(help="keep waiting when the world vanishes (for a new world "
                                             "of the run) instead of exiting 4")] = False,
    world_grace: Annotated[float, typer.Option(help="s to wait for a world that stopped answering (a "
                                               "frozen or cut-off world; exit 5 after that)", min=0.0)] = 10.0,
    connect_timeout: Annotated[float, typer.Option(help="s to wait for a world to listen on --connect before "
                                                   "giving up (exit 6)", min=0.0)] = 10.0,
    world_wait: Annotated[Optional[float], typer.Option(
        "--world-wait", hidden=True, min=0.0, help="the old name of --connect-timeout (deprecated)")] = None,
    credentials: CredentialsOpt = None,
    trust_law: TrustLawOpt = None,
) -> None:
    """Run one agent process; it takes its initial state from the world, so only its id is needed.

    It connects as agent-ID with the run's credentials: --credentials FILE, else
    $SWARM_CREDENTIALS, else the local run's file in the runtime directory. On another
    machine, use a file from `swarm credentials --agent ID` (see docs/resilience.md, "Agents on other
    machines").

    Exit codes: 0 the run ended, 1 crashed (e.g. an exception in its law), 3 refused,
    4 the world vanished (unless --wait-world), 5 the world did not answer within
    --world-grace, 6 no world to join (nothing listened on --connect for --connect-timeout
    s), 130/143 stopped.

    Example: swarm agent --id 3 --connect tcp/10.0.0.5:7447 --credentials agent-3.cred
    """
    from agents.process import run_agent

    if credentials is not None:  # a file that cannot be used: said now, not after waiting for the world
        from swarm.contracts import credentials as C
        from swarm.contracts.identities import CredentialsError

        try:
            C.read(credentials)
        except CredentialsError as e:
            raise fail(f"swarm agent {id}: {e}", 3) from None
    wait = connect_timeout if world_wait is None else world_wait
    raise typer.Exit(run_agent(id, connect, run, wait_world, world_grace=world_grace, creds_file=credentials,
                               trust=tuple(trust_law or ()), world_wait=wait))


def register(app: typer.Typer) -> None:
    """Add the run commands to the main app (`swarm up`: swarm/up_cli.py)."""
    app.command("sim")(sim)
    app.command("world")(world)
    app.command("agent")(agent)
