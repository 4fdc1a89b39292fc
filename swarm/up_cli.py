"""`swarm up`: a scenario as a distributed system (swarm/launcher.py), from the command
line: the progress line while it runs (swarm/up_progress.py), then the summary, the
plots, the agents that failed, one line on how it ended, and the exit code. The options
it shares with the other run commands are swarm/run_cli.py's."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.offline_cli import ScenarioArg, export_results, read_scenario, render_run_plots
from swarm.run_cli import (
    ClockOpt,
    DurationOpt,
    EndPlotsOpt,
    FoxgloveHostOpt,
    FoxgloveOpt,
    FoxglovePortOpt,
    ForceOpt,
    TimeScaleOpt,
    check_clock,
    check_duration,
    check_foxglove,
    check_runtime_dir,
    claim_out,
    new_run_id,
    out_option,
    print_summary,
)
from swarm.up_progress import progress_errors

UpOutOpt = out_option("output directory (default runs/<run id>); one that already holds results is "
                      "refused unless --force")


def up(
    scenario: ScenarioArg,
    out: UpOutOpt = None,
    duration: DurationOpt = None,
    clock: ClockOpt = None,
    time_scale: TimeScaleOpt = 1.0,
    listen: Annotated[Optional[str], typer.Option(help="endpoint of the run (default: a Unix socket in "
                                                  "$SWARM_RUNTIME_DIR or /tmp/swarm-<uid>)")] = None,
    plots: EndPlotsOpt = True,
    force: ForceOpt = False,
    world_grace: Annotated[float, typer.Option(help="s the agents wait for a world that stopped answering "
                                               "(a stalled, not a vanished, world)", min=0.0)] = 10.0,
    foxglove: FoxgloveOpt = False,
    foxglove_port: FoxglovePortOpt = 8765,
    foxglove_host: FoxgloveHostOpt = "127.0.0.1",
) -> None:
    """Run a scenario as a distributed system: a world process and one OS process per agent.

    Prints the endpoint and run id (so another terminal can attach), live progress, and a
    summary; writes summary.json, trajectory.npz, plots and logs/ into --out. Ctrl-C stops
    cleanly: results written, no process left behind, exit 130 (143 for SIGTERM).

    Example: swarm up scenarios/case2.toml --out runs/case2
    """
    from swarm.launcher import Launcher, UpConfig

    s = read_scenario(scenario)
    check_clock(clock)
    check_duration(s, duration, scenario)
    check_runtime_dir()
    live = (foxglove_host, foxglove_port) if foxglove else None
    if live is not None:
        check_foxglove(*live)
    run_id = new_run_id(scenario)
    out = out or Path("runs") / run_id
    claim_out(out, force)
    launcher = Launcher(UpConfig(scenario, s, out, run_id, listen, duration, clock, time_scale,
                                 world_grace=world_grace, foxglove=live))
    typer.echo(f"run {run_id}  endpoint {launcher.endpoint}  agents {len(s.agents)}  "
               f"clock {clock or s.run.clock}")
    for line in attach_hints(run_id, launcher.dial, s):
        typer.echo(line)
    if live is not None:
        from world.live_view import open_hint

        typer.echo(open_hint(*live))
    total = int(round((duration or s.run.duration) / s.run.dt))
    tty = sys.stdout.isatty()
    state = {"last": 0.0, "tick": 0, "wall": 0.0}

    def show(p, wall):
        if p is None or (p["tick"] == state["tick"] and state["wall"] > 0):
            return
        now = time.monotonic()
        if not tty and now - state["last"] < 1.0 and p["tick"] < total - 1:
            return
        rate = (p["tick"] - state["tick"]) / max(wall - state["wall"], 1e-9)
        state.update(last=now, tick=p["tick"], wall=wall)
        line = f"t={p['time']:7.2f}s tick {p['tick']}/{total} {rate:6.0f} ticks/s  " + progress_errors(p)
        if tty:  # one terminal row: a wrapped line would not be cleared by the next one
            import shutil

            typer.echo("\r\033[K" + line[:max(20, shutil.get_terminal_size().columns - 1)], nl=False)
        else:
            typer.echo(line)

    code = launcher.run(show)
    if tty:
        typer.echo("")
    code = _up_outcome(launcher, code, out)
    try:  # a world that died before writing its results: rebuild them from its recording
        export_results(out)
    except typer.Exit:
        pass  # said why in one line; the exit code stays the run's
    summary_path = out / "summary.json"
    if summary_path.exists():
        summary = json.loads(summary_path.read_text())
        print_summary(summary, out)
        if plots:
            render_run_plots(out)
    for r in launcher.exits if launcher.failure is None else []:
        typer.echo(f"  {r.line()}" + ("" if r.sent else "  (not in summary.json: the world did not hear of it)"))
    raise typer.Exit(code)


def attach_hints(run_id: str, dial: str, s) -> list[str]:
    """What to type in another terminal: watch the run (with --run when other runs are up,
    so the command cannot pick the wrong one), and add an agent by hand."""
    from swarm.contracts.credentials import local_runs

    try:
        others = any(c.run != run_id for c in local_runs())
    except Exception:  # an unreadable runtime dir: swarm up says so itself
        others = True
    pick = f" --run {run_id}" if others else ""
    ids = s.added_id_range
    lines = [f"watch it from another terminal: swarm watch{pick}  (table: swarm agents{pick}; graph: "
             f"swarm graph{pick}" + (f"; or export SWARM_RUN={run_id} once" if others else "") + ")",
             f"add an agent by hand: swarm spawn --id N{pick} (a new id, {ids.start}..{ids.stop - 1}, with "
             "--x --y --heading --speed)"]
    if not dial.startswith("unixsock"):
        lines.append(f"from another machine: swarm credentials --agent N{pick}, there swarm agent --id N --connect {dial} "
                     "--credentials FILE (README, \"Agents on other machines\")")
    return lines


EXIT_AGENT_FAILED = 4  # swarm up's exit codes: README, "What `swarm up` watches" (5: the world's own)


def _up_outcome(launcher, code: int, out: Path) -> int:
    """Say how the run ended (one line) and return `swarm up`'s exit code."""
    from world.clock import EXIT_DESERTED
    err = dict(err=True, fg=typer.colors.RED)
    if launcher.stop_signal is not None:
        typer.echo(f"stopped by signal {launcher.stop_signal}; partial results in {out}")
        return 128 + launcher.stop_signal
    if launcher.failure is not None:  # an agent could not start (said live), or no world to reach
        typer.secho(f"swarm up: {launcher.failure}; the run is stopped", **err)
        return EXIT_AGENT_FAILED if launcher.exits else 1
    if code not in (0, EXIT_DESERTED):
        from world.recording import EXIT_NO_SPACE

        typer.secho(f"swarm up: {launcher.world_failure()} (see {out / 'logs' / 'world.log'})", **err)
        return EXIT_NO_SPACE if code == EXIT_NO_SPACE else 1
    crashed = launcher.crashed()
    if crashed:
        typer.secho(f"swarm up: {len(crashed)} agent process(es) failed: {crashed[0].line()}", **err)
        return EXIT_AGENT_FAILED
    if code == EXIT_DESERTED:
        typer.secho("swarm up: the run ended early: no agent process was left", **err)
        return EXIT_DESERTED
    return 0


def register(app: typer.Typer) -> None:
    """Add `swarm up` to the main app."""
    app.command("up")(up)
