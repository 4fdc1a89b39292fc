"""The `swarm` command line: the root typer app, made of small command groups, each in its
own module and added here with its `register(app)`; failures are one message and an exit code.

    up_cli       up                             (run a scenario as processes)
    run_cli      sim, world, agent              (run a scenario, or a part of one)
    offline_cli  check, schema; plot, export    (no running swarm needed; plot_cli.py)
    live_cli     runs, agents, graph, watch     (read a live run)
    control_cli  kill, spawn, pause, resume     (act on a live run)
    access_cli   credentials                    (hand an identity to another machine)
    host_cli     host                           (agents of a run on this machine, via its router)
    study_cli    study swarms, study gains      (batch studies)
"""

from __future__ import annotations

import typer

from swarm import access_cli, control_cli, host_cli, live_cli, offline_cli, run_cli, up_cli
from swarm.study_cli import study_app

app = typer.Typer(
    help="swarm: an agent-per-process runtime for bearing-based circumnavigation over zenoh.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)

for group in (up_cli, run_cli, offline_cli, live_cli, control_cli, access_cli, host_cli):
    group.register(app)
app.add_typer(study_app, name="study")


def main() -> None:
    app()


if __name__ == "__main__":
    main()
