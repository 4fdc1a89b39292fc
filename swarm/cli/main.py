"""The `swarm` command line: the root typer app, made of small command groups, each in its
own module and added here with its `register(app)`. A command parses its options, calls the
Python API (`import swarm`) and renders what it returns; the API's errors become one line and
an exit code in one place (swarm/cli/errors.py, wrapped round every command here).

    up       up                             (run a scenario as processes)
    run      sim, world, agent              (run a scenario, or a part of one)
    offline  check, schema                  (no running swarm needed)
    plot     plot, export                   (a finished run's figures and files)
    live     runs, agents, graph            (read a live run)
    watch    watch                          (a live run in the terminal)
    control  kill, spawn, pause, resume     (act on a live run)
    access   credentials                    (hand an identity to another machine)
    host     host                           (agents of a run on this machine, via its router)
    study    study swarms, gains, scenario  (batch studies)
    tools    logs, stop, echo               (a live run's logs, its end, its streams)

Options several groups share are in `options`, shared output in `output`; command modules
never import each other.

`app` (every command) is built on first use. The `swarm` process of a live command builds
only that command's group (`LAZY`): a live command is a short query, and importing and
declaring every other command was most of its own time. So do `swarm up`, `swarm sim` and
the processes of a run (`swarm world`, `swarm agent`), started hundreds of times by the tests.
"""

from __future__ import annotations

import sys
from importlib import import_module

import typer

from swarm import __version__
from swarm.cli.errors import OneLineErrors, fail, map_app
from swarm.contracts import log as logs
from swarm.contracts.vocabulary import ExitCode

GROUPS = ("up", "run", "offline", "plot", "live", "watch", "control", "access", "host", "robots", "tools", "estop")
# command -> the group modules that are enough to run it (several commands in all: a typer app
# of one command would run it without its name)
LAZY = {
    name: modules
    for modules, names in (
        (("live", "watch"), ("runs", "agents", "graph", "watch")),
        (("control",), ("kill", "spawn", "pause", "resume")),
        (("tools",), ("logs", "stop", "echo")),
        (("estop", "tools"), ("estop",)),  # (one command alone would run without its name)
        # a run's own processes: `swarm world` (started by `swarm up`), `swarm up`, `swarm sim`,
        # `swarm agent` (about 0.1 s of CPU less each than building every command)
        (("run",), ("sim", "world", "agent")),
        (("up", "run"), ("up",)),
    )
    for name in names
}


def _print_version(value: bool) -> None:
    if value:
        from swarm.contracts import fastpath  # lazy: only --version says which wire path runs

        typer.echo(f"swarm {__version__}")
        typer.echo(f"wire path: {fastpath.path}")
        raise typer.Exit()


def set_up_logs(command: str | None, verbose: bool, quiet: bool) -> None:
    """This process's diagnostics, prefixed with the command's name ("swarm up: ...", "[up] ...";
    swarm/contracts/log.py); -v / -q set $SWARM_LOG_LEVEL, which the processes it starts inherit."""
    if verbose and quiet:
        raise fail("swarm: -v and -q together: give one", ExitCode.USAGE)
    if verbose or quiet:
        logs.set_level_env("DEBUG" if verbose else "WARNING")
    logs.setup(command or "swarm")


def build(groups=GROUPS, study: bool = True):
    """The typer app of these command groups (and `swarm study`), every command's errors mapped."""
    app = typer.Typer(
        cls=OneLineErrors,  # typer's usage errors (a bad option value...) as one line (swarm/cli/errors.py)
        help="swarm: an agent-per-process runtime for bearing-based circumnavigation over zenoh.",
        no_args_is_help=True,
        add_completion=False,
        pretty_exceptions_enable=False,
    )

    @app.callback()
    def root(
        ctx: typer.Context,
        version: bool = typer.Option(
            False, "--version", is_eager=True, callback=_print_version, help="print the version and exit"
        ),
        verbose: bool = typer.Option(
            False, "--verbose", "-v", help="debug lines too, in this process and the ones it starts (world, agents)"
        ),
        quiet: bool = typer.Option(
            False, "--quiet", "-q", help="warnings and errors only, in this process and the ones it starts"
        ),
    ) -> None:
        set_up_logs(ctx.invoked_subcommand, verbose, quiet)

    for group in groups:
        import_module(f"swarm.cli.{group}").register(app)
    if study:
        # lazy: a live command's process builds its own group only (LAZY), without `swarm study`
        from swarm.cli.study import study_app

        app.add_typer(study_app, name="study")
    map_app(app)  # the API's errors: one line on stderr and their exit code (swarm/cli/errors.py)
    return app


def __getattr__(name: str):
    if name == "app":
        value = globals()["app"] = build()
        return value
    raise AttributeError(f"module 'swarm.cli.main' has no attribute {name!r}")


FOXGLOVE_COMMANDS = ("up", "world", "watch")  # the commands with --foxglove [PORT]


GLOBAL_FLAGS = ("-v", "--verbose", "-q", "--quiet")  # the options of `swarm` itself, before the command


def command_at(argv: list[str]) -> int:
    """The index of the command's name in argv (after `swarm`'s own -v/-q); len(argv) if none."""
    k = 1
    while k < len(argv) and argv[k] in GLOBAL_FLAGS:
        k += 1
    return k


def foxglove_argv(argv: list[str]) -> list[str]:
    """`--foxglove PORT` and `--foxglove=PORT` (PORT all digits) as `--foxglove --foxglove-port
    PORT` for the commands of FOXGLOVE_COMMANDS (the command's name after `swarm`'s own -v/-q);
    everything else as it is, and nothing after `--`. typer cannot give an option a value that
    may be left out."""
    c = command_at(argv)
    if c >= len(argv) or argv[c] not in FOXGLOVE_COMMANDS:
        return list(argv)
    out, k = list(argv[: c + 1]), c + 1
    while k < len(argv):
        a = argv[k]
        if a == "--":
            return out + list(argv[k:])
        if a.startswith("--foxglove=") and a[len("--foxglove=") :].isdigit():
            out += ["--foxglove", "--foxglove-port", a[len("--foxglove=") :]]
        elif a == "--foxglove" and k + 1 < len(argv) and argv[k + 1].isdigit():
            out += ["--foxglove", "--foxglove-port", argv[k + 1]]
            k += 1
        else:
            out.append(a)
        k += 1
    return out


def main() -> None:
    sys.argv[:] = foxglove_argv(sys.argv)
    c = command_at(sys.argv)
    group = LAZY.get(sys.argv[c]) if c < len(sys.argv) else None
    (build(group, study=False) if group else __getattr__("app"))()


if __name__ == "__main__":
    main()
