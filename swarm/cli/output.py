"""What several commands print the same way: a run's summary table, its plots, a progress bar."""

from __future__ import annotations

import sys
from pathlib import Path

import typer

from swarm.cli.errors import fail
from swarm.contracts.vocabulary import ExitCode


def render_run_plots(out: Path, formats: tuple[str, ...] = ("png",)) -> None:
    """The figures of the run in `out` in `formats`, their names printed; a plotting failure exits 1."""
    from swarm.plots import PlotError, render_plots  # lazy: matplotlib (~0.3 s), which `swarm --help` must not pay

    try:
        files = render_plots(out, formats=formats)
    except PlotError as e:
        raise fail(str(e), ExitCode.FAILED) from None
    say_plots(files)


def say_plots(files: list[Path]) -> None:
    typer.echo("plots: " + ", ".join(p.name for p in files))


def _progress_bar(label: str):
    # lazy: rich.progress (~20 ms with rich), only while a run goes
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(
        TextColumn(label),
        BarColumn(),
        TextColumn("{task.completed}/{task.total} ticks"),
        TimeRemainingColumn(),
        transient=True,
        disable=not sys.stderr.isatty(),
    )


def robots_trust_line(robots: dict | None) -> str | None:
    """A robot run's refusals in one line (summary.json's `robots`), None when there were none:
    poses refused (another publisher's, or beyond a robot's limits), commands of another
    publisher on a robot's topic, the other publishers the world named."""
    if not robots:
        return None
    agents = robots.get("agents", {}).values()
    foreign = sum(a.get("refused_poses", {}).get("foreign", 0) for a in agents)
    implausible = sum(a.get("refused_poses", {}).get("implausible", 0) for a in agents)
    commands, others = robots.get("foreign_commands", 0), robots.get("other_publishers", [])
    if not (foreign or implausible or commands or others):
        return None
    parts = [
        f"{foreign + implausible} poses refused ({foreign} of another publisher, {implausible} beyond a robot's limits)"
    ]
    if commands:
        parts.append(f"{commands} commands of another publisher on a robot's topic")
    if others:
        parts.append("other publishers: " + ", ".join(others))
    return "robots: " + "; ".join(parts) + " (summary.json: robots; the world's log names them)"


def safety_line(safety: dict | None) -> str | None:
    """One line of a run's safety figures (summary.json's `safety`; None without a [safety] table)."""
    if not safety:
        return None
    d = safety.get("min_distance")
    what = "filter" if safety.get("enabled") else "measured only"
    return (
        f"safety ({what}, radius {safety['radius']:g} m): collisions {safety['collisions']}, "
        f"boundary exits {safety['boundary_exits']}, saturations {safety['saturations']}, "
        f"least distance {'-' if d is None else format(d, '.3g')} m, interventions {safety['interventions']}"
        + (f", no safe command {safety['infeasible']} agent-ticks" if safety.get("infeasible") else "")
    )


def print_summary(summary: dict, out: Path) -> None:
    typer.echo(
        f"converged: {summary['converged']}  ticks: {summary['ticks']}  "
        f"sim time: {summary['sim_time']:.2f} s  selection: {summary.get('selection', '-')}  "
        f"switches: {summary.get('switches', '-')}"
    )
    typer.echo(
        f"  {'id':>3} {'role':<8} {'out':>4} {'root':>4} {'radius':>9} {'expected':>9} "
        f"{'error %':>8} {'rate':>8} {'settle s':>8} {'switches':>8}"
    )
    for aid, a in summary["agents"].items():

        def f(v, fmt):
            return "-" if v is None else format(v, fmt)

        typer.echo(
            f"  {aid:>3} {a['role']:<8} {f(a['out_neighbour'], 'd'):>4} {f(a['root'], 'd'):>4} "
            f"{a['final_radius']:9.3f} {f(a['expected_radius'], '9.3f'):>9} "
            f"{f(None if a['relative_error'] is None else 100 * a['relative_error'], '8.3f'):>8} "
            f"{f(a['angular_rate'], '8.4f'):>8} {f(a['settling_time'], '8.2f'):>8} "
            f"{f(a.get('switches'), 'd'):>8}" + ("" if a["alive"] else "  (dropped)")
        )
    safety = safety_line(summary.get("safety"))
    if safety is not None:
        typer.echo(safety)
    robots_line = robots_trust_line(summary.get("robots"))
    if robots_line is not None:
        typer.secho(robots_line, fg=typer.colors.YELLOW)
    why = summary.get("not_reproducible") or []
    if summary.get("clock") == "lockstep" and summary.get("reproducible") is False and why:
        more = f" (and {len(why) - 1} more: summary.json, not_reproducible)" if len(why) > 1 else ""
        typer.echo(f"not what lockstep promises (swarm sim would differ): {why[0]}{more}")
    typer.echo(f"results: {out}")
