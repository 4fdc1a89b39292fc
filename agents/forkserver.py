"""A fork server for agent processes: one process that has imported everything an agent
needs forks every agent of a run, so N agents pay for the interpreter's start and the
imports once instead of N times (an agent's CPU until it has joined: 0.11 s exec'd; see
docs/benchmarks.md, "Forked agents", for what forking saves).

`swarm up` starts it (`python -m swarm.agents.forkserver`) in the run's process group, with the
agents' environment, once it has made itself a child subreaper (swarm/runtime/forks.py). One JSON
line each way on stdin / stdout:

    request   {"argv": ["7", "unixsock-stream//...", "case2-734b0c", "--world-grace", "10"],
               "log": "/path/logs/agent-7.log", "env": {"SWARM_CREDENTIALS": "..."}}
    reply     {"pid": 12345}          or   {"error": "why"}

and, once, before any reply: {"ready": true} when the imports are done.

`argv` is what `python -m swarm.agents.process` takes; `env` (optional) is added to the server's
environment, which is the agents' (`swarm host` gives each agent its own credentials file).
Each agent is forked twice: the middle process exits at once, so the agent is re-parented
to the launcher (the subreaper), which waits for it, reads its exit status and reaps it as
it would a process it had exec'd, and the server itself never has a child for longer than
a request. The agent waits to be re-parented before anything else, so that
`tie_to_launcher` (swarm/contracts/lifeline.py) sees the launcher as its parent (or, if the
launcher died meanwhile, sees that it did, and stops); its title (`ps`, /proc/PID/cmdline) is the command line it
would have had if exec'd, so tools that find agents by their command line still do.

The server ends at the end of its stdin (the launcher closed it, or died) and on SIGTERM.
Standard library and setproctitle only; imports the agent's modules so its children don't.
"""

from __future__ import annotations

import gc
import json
import os
import signal
import sys
import time
from typing import Any

import swarm.agents.brain  # noqa: F401  (imported here so that no agent has to)
import swarm.agents.laws  # noqa: F401
import swarm.agents.leader  # noqa: F401
import swarm.agents.process
from swarm.contracts.vocabulary import ExitCode

REPARENT_WAIT = 5.0  # s an agent waits to be re-parented (its middle process exits at once)


def serve(stdin: Any = None, stdout: Any = None) -> int:
    """Answer fork requests until stdin ends; 0."""
    stdin = stdin or sys.stdin.buffer
    out = (stdout or sys.stdout.buffer).fileno()
    # What is imported now stays shared with every agent: the collector of an agent never
    # visits (and so never copies) the pages of these objects.
    gc.collect()
    gc.freeze()
    os.write(out, b'{"ready": true}\n')  # imported: requests are answered in milliseconds from now on
    for line in iter(stdin.readline, b""):
        reply: dict[str, str | int]
        try:
            req = json.loads(line)
            argv, log = [str(a) for a in req["argv"]], str(req["log"])
            env = {str(k): str(v) for k, v in req.get("env", {}).items()}
        except (ValueError, KeyError, TypeError, AttributeError) as e:
            reply = {"error": f"bad request: {e}"}
        else:
            try:
                reply = {"pid": fork_agent(argv, log, env)}
            except OSError as e:
                reply = {"error": f"cannot fork agent: {e}"}
        os.write(out, json.dumps(reply).encode() + b"\n")
    return ExitCode.OK


def fork_agent(argv: list[str], log: str, env: dict[str, str] | None = None) -> int:
    """Fork an agent running `python -m swarm.agents.process *argv` (its output to `log`, `env`
    added to its environment), through a middle process that exits at once; its pid."""
    r, w = os.pipe()
    middle = os.fork()
    if middle == 0:  # the middle process: fork the agent, tell its pid, go
        try:
            os.close(r)
            me = os.getpid()
            pid = os.fork()
            if pid == 0:
                os.close(w)
                _become_agent(argv, log, env or {}, me)  # never returns
            os.write(w, str(pid).encode())
        finally:
            os._exit(ExitCode.OK)
    os.close(w)
    try:
        got = b""
        while chunk := os.read(r, 32):
            got += chunk
    finally:
        os.close(r)
        os.waitpid(middle, 0)
    if not got:
        raise OSError("the middle process did not fork")
    return int(got)


def reparented(middle: int, timeout: float) -> bool:
    """Wait until this process's parent is not `middle` any more (the launcher's, or init's if
    the launcher died); False after `timeout` s. `middle` is the pid the middle process had,
    not what getppid() says now: the middle may have exited before this process first looks."""
    t_end = time.monotonic() + timeout
    while os.getppid() == middle:
        if time.monotonic() >= t_end:
            return False
        time.sleep(0.001)
    return True


def _become_agent(argv: list[str], log: str, env: dict[str, str], middle: int) -> None:
    """In the forked agent: wait to be the launcher's, take the agent's title, output and
    default signals, run it, exit with its code."""
    code: int = ExitCode.FAILED
    try:
        reparented(middle, REPARENT_WAIT)
        os.environ.update(env)
        # the signals as a Python started afresh has them (SIGPIPE ignored: a write to a closed
        # socket is an error, not death); the agent installs its own SIGTERM / SIGINT handlers
        for sig, handler in (
            (signal.SIGTERM, signal.SIG_DFL),
            (signal.SIGCHLD, signal.SIG_DFL),
            (signal.SIGINT, signal.default_int_handler),
            (signal.SIGPIPE, signal.SIG_IGN),
        ):
            signal.signal(sig, handler)
        null = os.open(os.devnull, os.O_RDONLY)
        out = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        os.dup2(null, 0)
        os.dup2(out, 1)
        os.dup2(out, 2)
        os.close(null)
        os.close(out)
        _set_title([sys.executable, "-m", "swarm.agents.process", *argv])
        sys.argv = [swarm.agents.process.__file__, *argv]
        try:
            swarm.agents.process.main(argv)
            code = ExitCode.OK
        except SystemExit as e:
            code = e.code if isinstance(e.code, int) else (ExitCode.OK if e.code is None else ExitCode.FAILED)
    except BaseException:  # noqa: BLE001 (whatever it is, the log says it and the agent exits 1)
        import traceback  # lazy: only an agent that crashes needs it (the server imports little)

        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


def _set_title(argv: list[str]) -> None:
    try:
        import setproctitle  # lazy: optional (a convenience); loaded once, in the forked agent
    except ImportError:  # the title is a convenience: without it, `ps` shows the fork server's
        return
    setproctitle.setproctitle(" ".join(argv))


def main() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the launcher stops us (SIGTERM, or the end of stdin)
    sys.exit(serve())


if __name__ == "__main__":
    main()
