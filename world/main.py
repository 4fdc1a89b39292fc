"""The world process from start to end: `run_world`, what `swarm world` runs.

In order: SIGTERM/SIGINT become `Stop` from the first moment; the run's credentials are
written (world/hub_auth.py) and removed at the end however it ends; a stale Unix socket
of a crashed run is removed (a live one belongs to another run: refused); the `World`
(world/process.py) listens, runs its ticks and writes its results, which are written
even when it is stopped, after a disk-full error or a bug, so nothing recorded is lost.
Exit codes: 0 the run completed, 128+signal stopped, 2 cannot listen (the endpoint in
use or unusable, or the --foxglove port in use) or write the credentials, 3 agents did
not join in time, 1 an internal error, EXIT_NO_SPACE the recording or the results could
not be written, EXIT_DESERTED (world/clock.py) no agent was left.
"""

from __future__ import annotations

import signal
import sys

from swarm.contracts.identities import CredentialsError
from swarm.contracts.transport import socket_path
from world.hub_auth import forget_run, run_auth
from world.process import World, WorldConfig
from world.recording import EXIT_NO_SPACE, RecordingError


class Stop(BaseException):
    """Raised on the main thread by SIGTERM/SIGINT (a BaseException, so that no
    `except Exception` around publishing can swallow it)."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _raise_stop(signum, _frame):
    # One Stop only: a second Ctrl-C (or a SIGTERM after it) must not interrupt the
    # writing of the results that the first one started.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Stop(signum)


def run_world(cfg: WorldConfig) -> int:
    """Run a world to the end; exit code 0 when the run completed, 128+signal when stopped,
    EXIT_NO_SPACE when the recording or the results could not be written."""
    # Stop (SIGTERM/SIGINT) from the first moment: the run's credentials, once written,
    # must go with it however early it is stopped.
    old = {sig: signal.signal(sig, _raise_stop) for sig in (signal.SIGTERM, signal.SIGINT)}
    try:
        try:
            cfg.auth = run_auth(cfg.run, cfg.listen, cfg.scenario)
        except (CredentialsError, OSError) as e:
            print(f"swarm world: {e if isinstance(e, CredentialsError) else f'cannot write the run credentials: {e}'}",
                  file=sys.stderr)
            return 2
        return _run_world(cfg)
    except Stop as s:  # before the world listened: nothing recorded
        return 128 + s.signum
    finally:
        forget_run(cfg.run, cfg.listen)
        for sig, h in old.items():
            signal.signal(sig, h)


def _run_world(cfg: WorldConfig) -> int:
    sock = socket_path(cfg.listen)
    if sock is not None and sock.exists():
        # A stale socket from a crashed run blocks listening; a live one belongs to a run.
        import socket as so

        s = so.socket(so.AF_UNIX, so.SOCK_STREAM)
        try:
            s.connect(str(sock))
            s.close()
            print(f"swarm world: {cfg.listen} is in use by another run", file=sys.stderr)
            return 2
        except OSError:
            sock.unlink(missing_ok=True)
    try:
        world = World(cfg)
    except RecordingError as e:
        print(f"swarm world: {e}", file=sys.stderr)
        return EXIT_NO_SPACE
    code = 0  # SIGTERM/SIGINT raise Stop here (run_world installed the handlers)
    live = None  # the --foxglove server (world/live_view.py)
    try:
        if cfg.foxglove is not None:  # before listening: a port in use stops the run before it starts
            from world.live_view import LiveViewError, start_live_view

            try:
                live = start_live_view(world.engine.rec.writer, cfg.run, *cfg.foxglove)
            except LiveViewError as e:
                world.discard_recording()
                print(f"swarm world: {e}", file=sys.stderr)
                return 2
        try:
            world._open()
        except Stop as s:  # stopped before it listened: nothing to record
            world.discard_recording()
            return 128 + s.signum
        except Exception as e:  # zenoh.ZError: endpoint unusable
            world.discard_recording()
            print(f"swarm world: cannot listen on {cfg.listen}: {e}", file=sys.stderr)
            return 2
        if cfg.progress:
            if live is not None:
                from world.live_view import open_hint

                print(f"[world] {open_hint(*cfg.foxglove)}", file=sys.stderr, flush=True)
            print(f"[world] run {cfg.run} listening on {cfg.listen}", file=sys.stderr, flush=True)
        try:
            code = world.run()
        except Stop as s:
            world.stopped_by = s.signum
            code = 128 + s.signum
        except TimeoutError as e:
            print(f"swarm world: {e}", file=sys.stderr)
            code = 3
        except RecordingError as e:  # disk full mid-run: what reached the disk stays readable
            print(f"swarm world: {e}; stopping the run", file=sys.stderr)
            world.stopped_by = -1
            code = EXIT_NO_SPACE
        except Exception:  # a bug: say so, but still write what was recorded and close cleanly
            import traceback

            traceback.print_exc()
            print("swarm world: internal error; results so far are written", file=sys.stderr)
            world.stopped_by = -1
            code = 1
        # Results are written even when stopped: nothing recorded is lost.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        try:
            world.finish()
        except RecordingError as e:
            if code != EXIT_NO_SPACE:
                print(f"swarm world: {e}", file=sys.stderr)
            code = EXIT_NO_SPACE
        except Exception:  # a bug in writing the results: say so, and still close (end notice)
            import traceback

            traceback.print_exc()
            print(f"swarm world: internal error writing the results; recording.mcap in {cfg.out_dir} "
                  "keeps the run (swarm export)", file=sys.stderr)
            code = 1
        world._close()
    finally:
        if live is not None:
            live.stop()
        if sock is not None:
            sock.unlink(missing_ok=True)
    return code
