"""The one place where the command line turns an error of the API into its message and exit
code: swarm/cli/main.py wraps every command with `mapped`, so a command calls the API and lets
what it raises go. The project's own errors carry their exit code (swarm/contracts/errors.py); so do
those of the layers below (scenarios, run directories, recordings, endpoints): every one
subclasses `Coded` (swarm/contracts/vocabulary.py) and names its code in its class. Anything
else is a bug and keeps its traceback.

Two kinds of bad input are caught here for every command, before the command runs:

- an endpoint option (a parameter named `connect`, `listen` or `endpoint`: `--connect`,
  `--listen`, `--endpoint`, also when it comes from $SWARM_CONNECT) that is not an endpoint:
  one line, "--connect: not an endpoint: 'foo/bar' (...)", exit 2
  (swarm/contracts/endpoints.py);
- what typer itself refuses (a number out of its option's range, a value of the wrong type,
  an unknown or missing option): one line, "--duration -5: should be greater than or equal
  to 0", exit 2, instead of typer's usage box (`OneLineErrors`, the root app's class).
"""

from __future__ import annotations

import functools

import typer
from typer._click.exceptions import BadParameter, MissingParameter, NoArgsIsHelpError, UsageError
from typer.core import TyperCommand, TyperGroup

from swarm.contracts.errors import SwarmError, one_line
from swarm.contracts.stop_signals import CliStops, Stopped
from swarm.contracts.vocabulary import Coded, ExitCode

# the `swarm` process's stop handling (set by swarm/cli/__init__.py `main`; None in-process, e.g. under CliRunner)
cli_stops: CliStops | None = None

# parameters that are endpoints, checked before any command runs: name -> option, listening
ENDPOINT_PARAMS = {"connect": ("--connect", False), "listen": ("--listen", True), "endpoint": ("--endpoint", False)}


def fail(message: str, code: int = ExitCode.FAILED) -> typer.Exit:
    """Print `message` on stderr (red on a terminal); the Exit to raise with `code`."""
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def stop_code() -> int:
    """The exit code of a command that ended on Ctrl-C by itself: 130, or 143 when SIGTERM it was."""
    signum = cli_stops.signum if cli_stops is not None else None
    return 128 + signum if signum is not None else ExitCode.INTERRUPTED


def exit_code(e: BaseException) -> int | None:
    """The exit code of an API error, None for any other exception."""
    return int(e.exit_code) if isinstance(e, Coded) else None


def check_endpoints(params: dict) -> None:
    """EndpointError for the first endpoint parameter (ENDPOINT_PARAMS) that is not one."""
    # lazy: only a command given an endpoint needs swarm.contracts.endpoints; `swarm --help` starts without it
    from swarm.contracts.endpoints import check_endpoint

    for name, (option, listen) in ENDPOINT_PARAMS.items():
        if params.get(name) is not None:
            check_endpoint(params[name], listen=listen, what=option)


def mapped(command):
    """`command` with the API's errors as their message on stderr and their exit code; its
    endpoint options checked first."""

    @functools.wraps(command)
    def run(*args, **kwargs):
        stops = cli_stops
        if stops is not None:
            stops.running()  # SIGINT/SIGTERM from here on: Stopped, one line below
        try:
            check_endpoints(kwargs)
            return command(*args, **kwargs)
        except Stopped as e:  # a stop the command does not end on by itself (swarm/contracts/stop_signals.py)
            raise fail(stops.line(e.signum) if stops is not None else str(e), 128 + e.signum) from None
        except Exception as e:
            code = exit_code(e)
            if code is None:
                raise
            raise fail(one_line(e) if isinstance(e, SwarmError) else str(e), code) from None
        finally:
            if stops is not None:
                stops.ending()

    return run


def map_app(app: typer.Typer) -> None:
    """Wrap every command of `app` and of its sub-apps with `mapped`; their help shows flags
    as flags (`FlagCommand`, `FlagGroup`)."""
    for info in app.registered_commands:
        info.callback = mapped(info.callback)
        if info.cls in (None, TyperCommand):  # (typer's default: no class of its own)
            info.cls = FlagCommand
    for group in app.registered_groups:
        if group.typer_instance is not None:  # (always set by add_typer)
            cls = group.typer_instance.info.cls
            if not isinstance(cls, type) or cls is TyperGroup:  # (typer's default: no class of its own)
                group.typer_instance.info.cls = FlagGroup
            map_app(group.typer_instance)


class FlagsAsFlags:
    """Help that shows a flag (`--force`, `--plots/--no-plots`, `--help`) without a value:
    typer's rich help (0.29) prints a bool option's type, `<bool>`, in the column of what an
    option takes, as if the flag took a value. A flag without a metavar of its own gets an
    empty one (what its plain help shows)."""

    def get_params(self, ctx):
        params = super().get_params(ctx)  # type: ignore[misc]  # (a mixin: the class after it in the MRO has it)
        for p in params:
            if getattr(p, "is_flag", False) and p.metavar is None:
                p.metavar = ""
        return params


class FlagCommand(FlagsAsFlags, TyperCommand):
    """Every command's class (`map_app`)."""


class FlagGroup(FlagsAsFlags, TyperGroup):
    """Every command group's class but the root's (`map_app`)."""


def _value_of(e) -> str | None:
    """The value typer refused, when its check says (pydantic's error carries it)."""
    cause = e.__cause__
    try:
        value = cause.errors()[0]["input"]
    except Exception:
        return None
    return value if isinstance(value, str) else format(value, "g") if isinstance(value, float) else str(value)


def usage_line(e) -> str:
    """One line for a usage error of typer's: the option and value, and what is wrong with it
    ("--duration -5: should be greater than or equal to 0"), or typer's own sentence for an
    unknown or missing option, with where to look."""
    ctx = e.ctx
    path = " ".join(["swarm", *ctx.command_path.split()[1:]]) if ctx is not None else "swarm"  # (any prog name)
    where = f"; see {path} --help"
    if isinstance(e, BadParameter) and not isinstance(e, MissingParameter) and e.param is not None:
        opts = getattr(e.param, "opts", None) if getattr(e.param, "param_type_name", "") == "option" else None
        name = max(opts, key=len) if opts else e.param.get_error_hint().strip("'")
        why = " ".join(str(e.message).split()).rstrip(".")
        if why.startswith("Input should be "):
            why = why[len("Input ") :]
        value = _value_of(e)
        return f"{name}{'' if value is None else f' {value}'}: {why}"
    text = " ".join(e.format_message().split()).rstrip(".")
    return f"{path}: {text[:1].lower()}{text[1:]}{where}"


class OneLineErrors(FlagsAsFlags, TyperGroup):
    """The root app's class: typer's usage errors (in any command or group under it) as one
    line on stderr and exit 2, not typer's box (usage, hint and a framed message); flags shown
    as flags (`FlagsAsFlags`)."""

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except NoArgsIsHelpError:
            raise  # `swarm study` alone: its help
        except UsageError as e:
            raise fail(usage_line(e), e.exit_code) from None
