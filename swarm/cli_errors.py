"""The one place where the command line turns an error of the API into its message and exit
code: swarm/cli.py wraps every command with `mapped`, so a command calls the API and lets
what it raises go. The project's own errors carry their exit code (swarm/errors.py); those
of the layers below are in `EXIT_CODES`, by class (matched without importing their modules:
an instance's class is loaded already). Anything else is a bug and keeps its traceback.
"""

from __future__ import annotations

import functools

import typer

from swarm.errors import SwarmError, one_line

# (module, class) -> exit code, for errors raised below the API (their messages name what is wrong)
EXIT_CODES = {
    ("swarm.contracts.scenario", "ScenarioError"): 2,  # a bad scenario file, dict or option
    ("swarm.results", "OutDirError"): 2,  # --out holding results without --force
    ("world.run_reader", "RunReadError"): 1,  # a run directory that cannot be read (also PlotError)
    ("world.stream", "RecordingError"): 74,  # results that cannot be written (EX_IOERR)
}


def fail(message: str, code: int = 1) -> typer.Exit:
    """Print `message` on stderr (red on a terminal); the Exit to raise with `code`."""
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def exit_code(e: BaseException) -> int | None:
    """The exit code of an API error, None for any other exception."""
    if isinstance(e, SwarmError):
        return e.exit_code
    for cls in type(e).__mro__:
        code = EXIT_CODES.get((cls.__module__, cls.__qualname__))
        if code is not None:
            return code
    return None


def mapped(command):
    """`command` with the API's errors as their message on stderr and their exit code."""
    @functools.wraps(command)
    def run(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except Exception as e:
            code = exit_code(e)
            if code is None:
                raise
            raise fail(one_line(e) if isinstance(e, SwarmError) else str(e), code) from None

    return run


def map_app(app: typer.Typer) -> None:
    """Wrap every command of `app` and of its sub-apps with `mapped`."""
    for info in app.registered_commands:
        info.callback = mapped(info.callback)
    for group in app.registered_groups:
        map_app(group.typer_instance)
