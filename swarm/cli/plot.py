"""`swarm plot` and `swarm export`: a finished (or crashed) run's figures, animation and
CSV files, from its run directory (registered with the offline commands). Both open it with
`swarm.open_run` (which rebuilds a crashed run from its recording: `Results.recovered`, said
in one line) and draw with `Results.plot` / write with `Results.write_csv`."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.cli.errors import fail
from swarm.cli.output import say_plots
from swarm.contracts.vocabulary import Coded, ExitCode

RunDirArg = Annotated[Path, typer.Argument(help="a run directory written by swarm sim / swarm up")]
FORMAT_HELP = "figure format: png, pdf or svg; repeat it or give a comma list (-f png,pdf)"


def plot_formats(values: Optional[list[str]]) -> tuple[str, ...]:
    """The formats of --format (repeated and/or comma lists); exit 2 naming a bad one."""
    from swarm.plots import check_formats  # lazy: matplotlib (~0.3 s), which `swarm --help` must not pay

    try:
        return check_formats([f for v in (values or ["png"]) for f in v.split(",") if f.strip()])
    except ValueError as e:
        raise fail(f"--format: {e}", ExitCode.USAGE) from None


def _run_dir(run_dir: Path) -> None:
    if not run_dir.is_dir():
        raise fail(f"{run_dir}: not a directory", ExitCode.USAGE)


def open_results(run_dir: Path):
    """`swarm.open_run(run_dir)`, saying what was rebuilt from the recording (if anything)."""
    from swarm.api.runs import open_run  # lazy: numpy and the recording (~0.15 s), not for `swarm --help`

    results = open_run(run_dir)
    if results.recovered is not None:
        typer.echo(results.recovered.line())
    return results


def render_animation_cli(run_dir: Path, frames: int) -> None:
    """animation.gif with a progress bar (on a terminal); a read failure exits 1."""
    from rich.progress import BarColumn, Progress, TextColumn  # lazy: rich.progress, not for `swarm --help`

    # lazy: matplotlib (~0.3 s), which `swarm --help` must not pay
    from swarm.plots import PlotError, render_animation
    from swarm.plots.animate import FPS, gif_frames

    try:
        with Progress(
            TextColumn("animation"),
            BarColumn(),
            TextColumn("{task.completed}/{task.total} frames"),
            transient=True,
            disable=not sys.stderr.isatty(),
        ) as bar:
            task = bar.add_task("animation", total=None)
            path = render_animation(
                run_dir, max_frames=frames, progress=lambda i, n: bar.update(task, completed=i, total=n)
            )
    except PlotError as e:
        raise fail(str(e), ExitCode.FAILED) from None
    n = gif_frames(path)
    typer.echo(f"animation: {path.name} ({n} frames, {n / FPS:.1f} s at {FPS} frames/s)")


def plot(
    run_dir: RunDirArg,
    format: Annotated[Optional[list[str]], typer.Option("--format", "-f", help=FORMAT_HELP, show_default="png")] = None,
    animate: Annotated[
        bool, typer.Option("--animate", help="also write animation.gif: trails, graph edges and switches over the run")
    ] = False,
    frames: Annotated[int, typer.Option(help="at most this many animation frames, evenly spaced over the run")] = 200,
) -> None:
    """Re-render the figures of a run from its trajectory.npz and summary.json, and write
    foxglove-layout.json, a Foxglove layout for the run's own agents, next to them.

    A run whose world died before writing them is first rebuilt from its recording.mcap
    (as `swarm export` does).

    Example: swarm plot runs/case2 -f png,pdf --animate
    """
    formats = plot_formats(format)
    if frames < 2:
        raise fail(f"--frames: {frames} is too few (at least 2)", ExitCode.USAGE)
    _run_dir(run_dir)
    results = open_results(run_dir)
    say_plots(results.plot(formats=formats))
    write_run_layout(results, run_dir)
    if animate:
        render_animation_cli(run_dir, frames)


def write_run_layout(results, run_dir: Path) -> None:
    """foxglove-layout.json next to the figures: the run's own agents (a write failure: exit 1)."""
    # lazy: numpy (~0.1 s), loaded by then anyway, but `swarm --help` must not pay it
    from swarm.offline.layout import run_agents, write_layout

    a = results.arrays
    agents, extent, centre = run_agents(a["ids"], a["role"], a.get("x"), a.get("y"), a.get("target"))
    try:
        path = write_layout(run_dir, agents, extent, centre)
    except OSError as e:
        raise fail(f"{run_dir}: foxglove layout: {e.strerror or e}", ExitCode.FAILED) from None
    typer.echo(f"foxglove layout: {path.name} ({len(agents)} agents; Foxglove: Layouts > Import from file)")


def write_csvs(results) -> None:
    """csv/agent-<id>.csv for every agent of `results` (a read failure: RunReadError, exit 1)."""
    from swarm.offline.csv_export import CSV_DIR  # lazy: numpy and the recording (~0.14 s), not for `swarm --help`

    try:
        paths = results.write_csv()
    except OSError as e:
        raise fail(f"{results.run_dir / CSV_DIR}: {e.strerror or e}", ExitCode.FAILED) from None
    typer.echo(f"csv: {len(paths)} files in {CSV_DIR}/ ({paths[0].name} ... {paths[-1].name})")


def export(
    run_dir: RunDirArg,
    plots: Annotated[
        Optional[bool],
        typer.Option(
            "--plots/--no-plots",
            help="render the PNG plots too (default: when it rebuilds the results from the recording, or when "
            "neither --csv nor --ros2 is given)",
            show_default=False,
        ),
    ] = None,
    csv: Annotated[
        bool,
        typer.Option(
            "--csv",
            help="also write csv/agent-<id>.csv: one CSV per agent, a row per "
            "tick (columns: docs/reference/outputs.md#csv)",
        ),
    ] = False,
    ros2: Annotated[
        bool,
        typer.Option(
            "--ros2",
            help="also write ros2/ (replacing one there): a rosbag2 (MCAP, ROS 2 types) with per agent "
            "/agent_<id>/pose (PoseStamped), /agent_<id>/odom (Odometry) and /agent_<id>/cmd_vel (Twist), "
            "for ros2 bag and Foxglove; needs rosbags (the ros2 extra)",
        ),
    ] = False,
) -> None:
    """Rebuild trajectory.npz and summary.json of a run from its recording.mcap; with --csv,
    write its trajectory as one CSV per agent; with --ros2, as a rosbag2 with ROS 2 types.

    Results already written are kept. For a run whose world was killed: everything that reached the disk (all but the last
    second at most) becomes a valid run directory; the summary says "complete": false. With --csv or --ros2 it writes
    only those files (and the plots only if it rebuilt the results, or with --plots).

    Example: swarm export runs/case2-1a2b3c --csv
    """  # noqa: E501 (the help text as it was: typer keeps its line breaks)
    from swarm.offline.results import needs_export  # lazy: numpy and the recording (~0.14 s), not for `swarm --help`

    _run_dir(run_dir)
    if ros2:
        check_rosbags()
    recover = needs_export(run_dir)
    if not recover:
        if (run_dir / "recording.mcap").is_file():
            typer.echo(f"{run_dir}: trajectory.npz and summary.json are already there; nothing to recover")
        elif not (csv or ros2):
            raise fail(f"{run_dir}: no recording.mcap to export from", ExitCode.FAILED)
    if plots is None:  # what was asked: a bag or CSV files alone never redraw a complete run's figures
        plots = recover or not (csv or ros2)
    if not (recover or csv or ros2 or plots):
        return
    results = open_results(run_dir)
    if csv:
        write_csvs(results)
    if ros2:
        write_ros2_bag(results)
    if plots:
        say_plots(results.plot())


def check_rosbags() -> None:
    """Exit 2 with how to install it when rosbags (the `ros2` extra) is missing."""
    # lazy: numpy (~0.1 s), which the export loads anyway but `swarm --help` must not pay
    from swarm.offline.ros2_export import INSTALL_HINT, rosbags_available

    if not rosbags_available():
        raise fail(INSTALL_HINT, ExitCode.USAGE)


def write_ros2_bag(results) -> None:
    """ros2/ (a rosbag2 with ROS 2 types) from `results` (a read failure: exit 1)."""
    from swarm.offline.ros2_export import write_ros2  # lazy: numpy (~0.1 s), not for `swarm --help`

    try:
        bag = write_ros2(results.run_dir, results.arrays, results.summary)
    except Coded as e:
        raise fail(str(e), e.exit_code) from None
    typer.echo(bag.line())


def register(app: typer.Typer) -> None:
    """Add `swarm plot` and `swarm export` to the main app."""
    app.command("plot")(plot)
    app.command("export")(export)
