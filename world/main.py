"""The world process from start to end: `run_world`, what `swarm world` runs.

In order: SIGTERM/SIGINT become `Stop` from the first moment (held back while the hub
opens, so that the session, once open, is always closed: an open one hangs the exit);
the files of killed worlds are swept from the runtime dir (swarm/contracts/runtime_sweep.py);
the run's credentials are written (world/hub_auth.py) and removed at the end however it
ends; a stale Unix socket of a crashed run is removed (a live one belongs to another run:
refused); the `World` (world/process.py) listens, says `ready` to the launcher (a pipe,
swarm/contracts/startup.py, with each step before), runs its ticks and writes its
results, which are written even when it is stopped, after a disk-full error or a bug, so
nothing recorded is lost. A world with a plant (world/plant.py: robots) prepares it before
it listens (a plant that cannot be used ends the world with its error's exit code before
any agent is started) and stops it on every way out, first thing after the last tick.
Exit codes (swarm/contracts/vocabulary.py, `ExitCode`): OK the run completed, 128+signal
stopped, USAGE cannot listen (the endpoint in use or unusable, or the --foxglove port in
use) or write the credentials, JOIN_TIMEOUT agents did not join in time, FAILED an
internal error, NO_SPACE the recording or the results could not be written, DESERTED
(world/clock.py) no agent was left.
"""

from __future__ import annotations

import logging
import traceback
from typing import Any

from swarm.contracts import log as logs
from swarm.contracts.identities import CredentialsError
from swarm.contracts.runtime_sweep import sweep_stale, unix_socket_answers
from swarm.contracts.startup import Announcer
from swarm.contracts.stop_signals import StopSignals
from swarm.contracts.transport import runtime_dir, socket_path
from swarm.contracts.vocabulary import Coded, ExitCode, signal_exit
from swarm.world.hub_auth import forget_run, run_auth
from swarm.world.live_view import LiveViewError, open_hint, start_live_view
from swarm.world.memory import limit_arenas
from swarm.world.process import World, WorldConfig
from swarm.world.recording import RecordingError

log = logging.getLogger(__name__)


class Stop(BaseException):
    """Raised on the main thread by SIGTERM/SIGINT (a BaseException, so that no
    `except Exception` around publishing can swallow it)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def run_world(cfg: WorldConfig) -> int:
    """Run a world to the end; exit code OK when the run completed, 128+signal when stopped,
    NO_SPACE when the recording or the results could not be written (see the module)."""
    logs.setup("world")  # "[world] ..." notes, "swarm world: ..." errors (swarm/contracts/log.py)
    log.debug(
        "run %s: %d agents, %s clock, endpoint %s, results in %s",
        cfg.run,
        len(cfg.scenario.agents),
        cfg.clock,
        cfg.listen,
        cfg.out_dir or "none (no --out)",
    )
    limit_arenas()  # before zenoh's and foxglove's threads start (world/memory.py)
    # Stop (SIGTERM/SIGINT) from the first moment: the run's credentials, once written,
    # must go with it however early it is stopped; held back while the hub opens
    # (swarm/contracts/stop_signals.py), so that an open session is always closed.
    stops = StopSignals(Stop).install()
    tell = Announcer.from_environment()  # the launcher's pipe (swarm/contracts/startup.py)
    try:
        tell.say("credentials")
        try:
            with stops.held():  # no stop half-way through writing a file (its temporary would stay)
                sweep_stale(runtime_dir())  # files of worlds that were killed (their pid is gone)
                cfg.auth = run_auth(cfg.run, cfg.listen, cfg.scenario)
        except (CredentialsError, OSError) as e:
            log.error("%s", e if isinstance(e, CredentialsError) else f"cannot write the run credentials: {e}")
            return ExitCode.USAGE
        return _run_world(cfg, stops, tell)
    except Stop as s:  # before the world listened: nothing recorded
        return signal_exit(s.signum)
    finally:
        stops.ignore()
        forget_run(cfg.run, cfg.listen)
        tell.close()
        stops.restore()


def _free_socket(sock: Any) -> bool:
    """Remove a stale socket of a crashed run; False when a live one (another run's) answers."""
    if sock is None or not sock.exists():
        return True
    if unix_socket_answers(sock):
        return False
    sock.unlink(missing_ok=True)
    return True


def _run_world(cfg: WorldConfig, stops: StopSignals, tell: Announcer) -> int:
    sock = socket_path(cfg.listen)
    if not _free_socket(sock):
        log.error("%s is in use by another run", cfg.listen)
        return ExitCode.USAGE
    tell.say("recording")
    try:
        world = World(cfg)
    except RecordingError as e:
        log.error("%s", e)
        return ExitCode.NO_SPACE
    live = None  # the --foxglove server (world/live_view.py)
    try:
        if cfg.foxglove is not None:  # before listening: a port in use stops the run before it starts
            try:
                live = start_live_view(world.rec.writer, cfg.run, *cfg.foxglove)
            except LiveViewError as e:
                world.discard_recording()
                log.error("%s", e)
                return ExitCode.USAGE
        if cfg.plant is not None:
            tell.say("robots")
            code = _prepare_plant(world, cfg, stops)
            if code is not None:
                return code
        tell.say("listening")
        try:
            # a stop comes once the session is the world's, to be closed (the hub opens in
            # milliseconds; its user dictionary file is written and removed meanwhile)
            with stops.held():
                world._open()
        except Stop as s:  # stopped while it opened: nothing to record; the session is closed again
            stops.ignore()
            world.discard_recording()
            world._close()
            return signal_exit(s.signum)
        except Exception as e:  # zenoh.ZError: endpoint unusable
            world.discard_recording()
            log.error("cannot listen on %s: %s", cfg.listen, e)
            return ExitCode.USAGE
        try:
            return _serve(world, cfg, live, stops, tell)
        finally:  # however it ends (a stop while handling another ending too), the session closes
            stops.ignore()
            world._close()
    finally:
        if cfg.plant is not None:  # (stopped already unless the run never got to its ticks)
            stops.ignore()  # the world ends: nothing may interrupt stopping the robots
            _stop_plant(world)
        if live is not None:
            live.stop()
        if sock is not None:
            sock.unlink(missing_ok=True)


def _prepare_plant(world: World, cfg: WorldConfig, stops: StopSignals) -> int | None:
    """Get the plant ready before the world listens (robots: reached, their command types
    known, their first poses in); None when it is, else the world's exit code, said in one
    line. Stopped meanwhile (SIGINT/SIGTERM, `Stop`): 128 + signal."""
    assert cfg.plant is not None
    try:
        cfg.plant.prepare()
        return None
    except Stop as s:
        code = signal_exit(s.signum)
    except Coded as e:  # the plant's own words: the robot and the topic
        log.error("%s", e)
        code = e.exit_code
    except Exception:
        _traceback()
        log.error("internal error while preparing the robots")
        code = ExitCode.FAILED
    stops.ignore()  # the world ends here: nothing may interrupt stopping the robots
    _stop_plant(world)
    world.discard_recording()
    return code


def _stop_plant(world: World) -> None:
    """Stop the plant (once: later calls do nothing); its own error is said, not raised, so
    that the results are still written and the session closed."""
    try:
        world.engine.stop_plant()
    except Exception:
        _traceback()
        log.error("internal error while stopping the robots")


def _serve(world: World, cfg: WorldConfig, live: Any, stops: StopSignals, tell: Announcer) -> int:
    """The run, listening, from its first tick to its results; its exit code."""
    code: int = ExitCode.OK
    try:
        tell.ready()
        if cfg.progress:
            if live is not None and cfg.foxglove is not None:
                log.info("%s", open_hint(*cfg.foxglove))
            log.info("run %s listening on %s", cfg.run, cfg.listen)
        code = world.run()
    except Stop as s:
        world.stopped_by = s.signum
        code = signal_exit(s.signum)
    except TimeoutError as e:
        log.error("%s", e)
        code = ExitCode.JOIN_TIMEOUT
    except RecordingError as e:  # disk full mid-run: what reached the disk stays readable
        log.error("%s; stopping the run", e)
        world.stopped_by = -1
        code = ExitCode.NO_SPACE
    except Exception:  # a bug: say so, but still write what was recorded and close cleanly
        _traceback()
        log.error("internal error; results so far are written")
        world.stopped_by = -1
        code = ExitCode.FAILED
    # The robots stop first (a Stop while stopping them is ignored from here on), then the
    # results are written, even when stopped: nothing recorded is lost.
    stops.ignore()
    _stop_plant(world)
    try:
        world.finish()
    except RecordingError as e:
        if code != ExitCode.NO_SPACE:
            log.error("%s", e)
        code = ExitCode.NO_SPACE
    except Exception:  # a bug in writing the results: say so, and still close (end notice)
        _traceback()
        log.error("internal error writing the results; recording.mcap in %s keeps the run (swarm export)", cfg.out_dir)
        code = ExitCode.FAILED
    return code


def _traceback() -> None:
    """The exception being handled, its traceback as Python prints it, before the line that
    says what failed (the log's last line, the cause `swarm up` reports)."""
    log.error("%s", traceback.format_exc().rstrip(), extra=logs.VERBATIM)
