"""The `swarm` command line (`main`), one module per command group; options shared by several
groups are in `options`, errors become one line and an exit code in `errors`.

`main` (the entry point, `swarm.cli:main`, and `python -m swarm`) takes SIGINT and SIGTERM
over before it imports anything else (swarm/contracts/stop_signals.py `CliStops`): a stop at
any moment, even during the imports, is one line and exit 128 + signum, never a traceback."""


def main() -> None:
    """The `swarm` command: stops handled from here on, then the command line (swarm/cli/main.py)."""
    # lazy: all of them, so that importing swarm.cli costs nothing and the stops come first
    import _signal  # type: ignore[import-not-found]  # (built in: `signal` takes ms on a loaded machine)
    import os
    import sys

    args = sys.argv[1:]
    while args[:1] and args[0] in ("-v", "--verbose", "-q", "--quiet"):  # `swarm`'s own (swarm/cli/main.py)
        args = args[1:]
    prog = " ".join(["swarm", *[w for w in args[:1] if not w.startswith("-")]])

    def first(signum, _frame):  # until CliStops is in place: the same line and exit, at once
        os.write(2, f"{prog}: stopped by {'SIGINT' if signum == _signal.SIGINT else 'SIGTERM'}\n".encode())
        os._exit(128 + signum)

    for sig in (_signal.SIGINT, _signal.SIGTERM):
        _signal.signal(sig, first)
    from swarm.contracts.stop_signals import CliStops  # lazy: after the first handler (see the module)

    stops = CliStops(prog).install()
    if args[:1] == ["estop"]:  # the robots first: zero twists before typer and the commands load
        from swarm.cli.estop_first import first as zero_first  # lazy: (see the module)

        zero_first(args[1:])
    from importlib import import_module  # lazy: (see the module)

    cli = import_module("swarm.cli.main")  # (the heavy imports: typer, the commands' modules)
    globals()["main"] = main  # (importing it made the name `swarm.cli.main` the module)
    from swarm.cli import errors  # lazy: loaded by swarm.cli.main by now

    errors.cli_stops = stops  # once a command runs, a stop is raised in it (`mapped`)
    try:
        cli.main()
    finally:
        stops.ending()


__all__ = ["main"]
