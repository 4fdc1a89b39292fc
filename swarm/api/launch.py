"""`swarm.launch(...)`: `swarm up` in this process, until the run ends (what `swarm up`
itself calls; `swarm.up(...)`, swarm/api/up.py, is the same run as a child process and a handle).

    outcome = swarm.launch("scenarios/case2.toml", clock="lockstep", duration=20, out="runs/x")
    outcome.exit_code, outcome.summary.converged    # swarm up's exit code; summary.json
    outcome.results()                               # swarm.open_run(outcome.out)

The launcher (swarm/runtime/launcher.py) starts the world and one process per agent, supervises
them and returns once the world has ended; then a world that died is rebuilt from its
recording (`UpOutcome.recovered`) and the summary read. Everything is checked before any
process starts: a bad scenario raises ScenarioError, a bad clock UsageError, an `out` that
holds results OutDirError. `progress(figures)` is called with what swarm up's progress line
shows; `on_start(launch)` once the run id and endpoint are known, before any process, with
the `Launch`, whose `stop(signum)` (from a signal handler or another thread) stops the run
as Ctrl-C does: the world writes the results, exit code 128 + signum. Called from the main
thread with `signals=True` (the default), SIGINT and SIGTERM call it while the run goes.
"""

from __future__ import annotations

import json
import re
import secrets
import shutil
import signal
import tempfile
import threading
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from swarm.api.record import Summary
from swarm.api.scenario import as_scenario, source_of, to_toml, with_duration
from swarm.contracts.errors import UsageError
from swarm.contracts.vocabulary import ExitCode, signal_exit
from swarm.offline.results import Recovery, claim_out_dir, recover
from swarm.robots.config import check_against, load_robots
from swarm.runtime.launcher import Launcher, UpConfig
from swarm.world.files import RecordingError

if TYPE_CHECKING:  # (numpy: the launcher imports none, swarm/api/record.py)
    from swarm.api.runs import Results

__all__ = ["Launch", "UpOutcome", "launch"]


@dataclass
class UpOutcome:
    """How a run of `launch` ended: `exit_code` (swarm up's), `words` (the one line saying
    how it ended, None when it went well; `failed`: a failure, which swarm up prints on
    stderr), `summary` (summary.json, None if none was written), `exits` (the agent
    processes that exited by themselves: swarm.runtime.supervision.AgentExitReport), `failure` (why
    the run could not start), `recovered` / `recovery_error` (results rebuilt from the
    recording of a world that died, or why they could not be), `stop_signal`, `run_id`, `out`."""

    exit_code: int
    words: str | None
    failed: bool
    run_id: str
    out: Path
    summary: Summary | None = None
    exits: list = field(default_factory=list)
    failure: str | None = None
    recovered: Recovery | None = None
    recovery_error: str | None = None
    stop_signal: int | None = None

    def results(self) -> Results:
        """The run's results: `swarm.open_run(out)`."""
        from swarm.api.runs import open_run  # lazy: numpy (see swarm/api/record.py)

        return open_run(self.out)


def name_stem(scenario: Any, s) -> str:
    """A scenario's name for run ids and directories: its file's stem, else its own name."""
    stem = Path(scenario).stem if isinstance(scenario, (str, Path)) else (s.name or "scenario")
    return re.sub(r"[^A-Za-z0-9_.-]", "-", stem)[:40]


def new_run_id(scenario: Any, s=None) -> str:
    """A new run id: the scenario's name stem and 6 random hex digits (`case2-734b0c`)."""
    return f"{name_stem(scenario, s) or 'run'}-{secrets.token_hex(3)}"


def scenario_file(scenario: Any, s) -> tuple[Path, str | None]:
    """The file the world reads: `scenario` itself, or `s` written as TOML into a new
    temporary directory (returned too, for the caller to remove)."""
    if isinstance(scenario, (str, Path)):
        return Path(scenario), None
    tmp = tempfile.mkdtemp(prefix="swarm-up-")
    path = Path(tmp) / f"{name_stem(scenario, s) or 'scenario'}.toml"
    path.write_text(to_toml(s), encoding="utf-8")
    return path, tmp


def check_clock(clock: str | None) -> None:
    if clock not in (None, "lockstep", "realtime"):
        raise UsageError(f"clock must be 'lockstep' or 'realtime', not {clock!r}")


def check_robots(robots: str | Path, s, clock: str | None) -> list[str]:
    """A robots file for scenario `s`: RobotsError (exit 2) when it cannot be read or does not fit
    the scenario, UsageError with the lockstep clock (robots run the realtime clock only); the
    warnings of the file against the scenario (swarm/robots/config.py `check_against`)."""
    if clock == "lockstep":
        raise UsageError(
            "robots run the realtime clock only (robots do not wait for a lockstep tick): "
            "clock 'lockstep' cannot drive them"
        )
    return check_against(load_robots(robots), s, str(robots))


class Launch:
    """A run of `scenario` checked and ready (nothing started yet): `run_id`, `out`,
    `endpoint` (where the world listens), `dial` (where its clients connect), `scenario`;
    `run()` runs it, `stop(signum)` stops it. The options are `launch`'s."""

    def __init__(
        self,
        scenario: Any,
        out: str | Path | None = None,
        *,
        force: bool = False,
        duration: float | None = None,
        clock: str | None = None,
        time_scale: float = 1.0,
        listen: str | None = None,
        foxglove: tuple[str, int] | None = None,
        world_grace: float = 10.0,
        say: Callable[[str], None] | None = None,
        robots: str | Path | None = None,
    ):
        s = as_scenario(scenario)
        with_duration(s, duration, source_of(scenario))
        check_clock(clock)
        self.warnings: list[str] = []  # the robots file's, against the scenario (said once, here)
        if robots is not None:
            self.warnings = check_robots(robots, s, clock)
            clock = "realtime"
        self.scenario = s
        self.run_id = new_run_id(scenario, s)
        self.out = Path(out) if out is not None else Path("runs") / self.run_id
        claim_out_dir(self.out, force)
        self.ticks = int(round((duration or s.run.duration) / s.run.dt))
        path, tmp = scenario_file(scenario, s)
        # A temporary scenario file goes when the run is over, or with this object if it never runs.
        self._forget_tmp = weakref.finalize(self, shutil.rmtree, tmp, True) if tmp is not None else None
        cfg = UpConfig(
            path,
            s,
            self.out,
            self.run_id,
            listen,
            duration,
            clock,
            time_scale,
            world_grace=world_grace,
            foxglove=foxglove,
            robots=Path(robots) if robots is not None else None,
        )
        self.launcher = Launcher(cfg) if say is None else Launcher(cfg, say)
        self.endpoint, self.dial = self.launcher.endpoint, self.launcher.dial
        if robots is not None:  # every robot zero-twisted as soon as the world exits, whatever ends it
            from swarm.robots.run_record import WorldExitStop  # lazy: zenoh and swarm.ros2, for --robots only

            la = self.launcher
            la.world_exit = WorldExitStop(
                load_robots(robots), Path(robots), self.run_id, la.say, ran=lambda: la.started
            )
        for w in self.warnings:
            self.launcher.say(f"warning: robots: {w}")

    def stop(self, signum: int = signal.SIGTERM) -> None:
        """Stop the run as signal `signum` does (exit code 128 + signum, results written).
        Callable from a signal handler or another thread, before or while `run` runs."""
        self.launcher.stop(signum)

    def run(self, progress: Callable[[dict], None] | None = None, signals: bool = True) -> UpOutcome:
        """Start the world and the agents, supervise them until the world ends; then rebuild
        the results of a world that died and read the summary. `progress(figures)`: the
        latest ground truth's figures (swarm/runtime/progress.py `truth_progress`: tick, time,
        errors, dropped) with `wall` (s since the agents started) and `ticks` (the run's)."""

        def show(p, wall):
            if p is not None and progress is not None:
                progress({**p, "wall": wall, "ticks": self.ticks})

        try:
            with stop_on_signals(self.stop if signals else None):
                code = self.launcher.run(show)
        finally:
            if self._forget_tmp is not None:
                self._forget_tmp()
        return self.outcome(code)

    def outcome(self, code: int) -> UpOutcome:
        """How the run ended (the launcher's state and the world's exit `code`), its results
        rebuilt if the world died first, its summary read."""
        la, out = self.launcher, self.out
        exit_code, words, failed = ending(la, code, out)
        o = UpOutcome(
            int(exit_code),  # a plain int, as it always was (ExitCode's aliases would name it oddly)
            words,
            failed,
            self.run_id,
            out,
            exits=list(la.exits),
            failure=la.failure,
            stop_signal=la.stop_signal,
        )
        try:
            o.recovered = recover(out)
        except (ValueError, RecordingError) as e:  # the exit code stays the run's
            o.recovery_error = str(e)
        summary = out / "summary.json"
        if summary.exists():
            o.summary = Summary(json.loads(summary.read_text()))
        return o


def launch(
    scenario: Any,
    out: str | Path | None = None,
    *,
    progress: Callable[[dict], None] | None = None,
    on_start: Callable[[Launch], None] | None = None,
    signals: bool = True,
    **options: Any,
) -> UpOutcome:
    """Run `scenario` (a file, a Scenario, a dict or a Builder) as `swarm up` does, in this
    process, until it ends; its `UpOutcome`. Options (`Launch`): out (default
    runs/<run id>; one holding results is refused unless force=True), force, duration (s),
    clock ("lockstep" | "realtime"), time_scale, listen (endpoint), foxglove ((host, port):
    serve the live view), world_grace (s), say (the launcher's live lines; default: printed),
    robots (a robots file: the world drives ROS 2 robots, docs/guides/robots.md; the realtime
    clock, whatever the scenario says; RobotsError for a file that does not fit the scenario).
    A scenario that is not a file is written to a temporary one: a law of its own is found
    on $SWARM_LAW_PATH only (pass its file to have its directory searched)."""
    run = Launch(scenario, out, **options)
    if on_start is not None:
        on_start(run)
    return run.run(progress, signals)


class stop_on_signals:
    """While in the block: SIGINT and SIGTERM call `stop(signum)` (nothing outside the main
    thread, where Python cannot handle signals, or with `stop` None); the handlers before are
    put back after."""

    def __init__(self, stop: Callable[[int], None] | None):
        self.stop = stop if threading.current_thread() is threading.main_thread() else None
        self.saved: dict = {}

    def __enter__(self) -> stop_on_signals:
        if self.stop is not None:
            stop = self.stop
            self.saved = {
                sig: signal.signal(sig, lambda signum, _frame: stop(signum)) for sig in (signal.SIGINT, signal.SIGTERM)
            }
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self.saved.items():
            signal.signal(sig, handler)


def ending(launcher, code: int, out: Path) -> tuple[int, str | None, bool]:
    """swarm up's exit code, the line saying how the run ended (None: it went well), and
    whether that is a failure, from the launcher's state and the world's exit `code`
    (docs/reference/exit-codes.md#swarm-up)."""
    if launcher.stop_signal is not None:
        who = getattr(launcher, "operator_stop", None)  # `swarm stop` from another terminal
        how = f"stopped by `swarm stop` ({who})" if who else f"stopped by signal {launcher.stop_signal}"
        if not (out / "summary.json").exists() and not (out / "recording.mcap").exists():  # stopped as it started
            logs = f" (logs in {out / 'logs'})" if (out / "logs").is_dir() else ""
            return signal_exit(launcher.stop_signal), f"{how} before the run started: no results{logs}", False
        return signal_exit(launcher.stop_signal), f"{how}; partial results in {out}", False
    if launcher.failure is not None:  # an agent could not start (said live), or no world to reach
        failed = ExitCode.AGENT_FAILED if launcher.exits else ExitCode.FAILED
        return failed, f"swarm up: {launcher.failure}; the run is stopped", True
    if code not in (ExitCode.OK, ExitCode.DESERTED):
        return (
            ExitCode.NO_SPACE if code == ExitCode.NO_SPACE else ExitCode.FAILED,
            f"swarm up: {launcher.world_failure()} (see {out / 'logs' / 'world.log'})",
            True,
        )
    crashed = launcher.crashed()
    if crashed:
        return ExitCode.AGENT_FAILED, f"swarm up: {len(crashed)} agent process(es) failed: {crashed[0].line()}", True
    if code == ExitCode.DESERTED:
        return ExitCode.DESERTED, "swarm up: the run ended early: no agent process was left", True
    return ExitCode.OK, None, False
