"""Acting on a live run: signal an agent's process (`signal_agent`, then `wait_dropped`) and
start one here (`spawn_agent`), on an open `swarm.live.client.LiveRun`. No printing: the results
are records, and what cannot be done is a `LiveError` (exit 1) or a `UsageError` (exit 2)
with one line saying why (swarm/contracts/errors.py). `swarm kill` and `swarm spawn`
(swarm/cli/control.py) and `swarm.connect(...)` (swarm/api/live.py) are made of these.

A signal goes by `os.kill` when the agent's host is this machine and its pid is still that
agent's process (checked in /proc/<pid>/cmdline: pids get reused, host names repeat), and
otherwise over zenoh (`agent/<id>/ctl`: the agent signals itself; SIGCONT cannot go that way).
"""

from __future__ import annotations

import json
import os
import signal as sig
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from swarm.contracts.credentials import ENV_CREDENTIALS
from swarm.contracts.errors import LiveError, NoRunError, UsageError
from swarm.contracts.identities import CredentialsError, agent_user
from swarm.contracts.laws import ENV_TRUSTED_LAWS, with_trusted_laws
from swarm.contracts.transport import runtime_dir
from swarm.runtime.procs import agent_id_of, command_words, wait_until

SPAWN_DEADLINE = 10.0  # s for a spawned agent to show up alive in the world's info
DROP_DEADLINE = 3.0  # s for a signalled agent to be dropped (SIGSTOP: the 1 s link lease)

SIGNALS = {"KILL": sig.SIGKILL, "TERM": sig.SIGTERM, "STOP": sig.SIGSTOP, "CONT": sig.SIGCONT}


@dataclass(frozen=True)
class Signalled:
    """A signal sent to agent `agent` (`how`: "sent" here, or "asked over zenoh to take");
    `live`: the agent was live in the world then (so a drop is to be expected)."""

    agent: int
    signal: str
    pid: int
    host: str | None
    how: str
    live: bool

    def line(self) -> str:
        return f"{self.how} SIG{self.signal} to agent {self.agent} (pid {self.pid} on {self.host})"

    @property
    def drops(self) -> bool:
        """Whether the world is to drop the agent for it (KILL, TERM, STOP of a live agent)."""
        return self.live and self.signal != "CONT"


@dataclass(frozen=True)
class Spawned:
    """An agent process started here that the world shows live."""

    agent: int
    pid: int
    log: Path

    def line(self) -> str:
        return f"agent {self.agent} is live: pid {self.pid} (log {self.log})"


def signal_name(name: str) -> str:
    """KILL, TERM, STOP or CONT from e.g. "kill", "SIGKILL"; UsageError for another."""
    n = name.upper().removeprefix("SIG")
    if n not in SIGNALS:
        raise UsageError(f"--signal {name!r}: use one of {', '.join(SIGNALS)}")
    return n


def looks_like_agent(pid: int, agent_id: int) -> bool:
    """Whether local process `pid` is still agent `agent_id`'s (not a reused pid)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
    except FileNotFoundError:
        return False
    except OSError:
        return True  # no /proc here: trust the pid
    parts = [a.decode(errors="replace") for a in argv]
    found = agent_id_of(parts)  # `python -m swarm.agents.process ID ...`, exec'd or forked (titled)
    if found is not None:
        return found == agent_id
    args = command_words(parts)
    if "agent" in args and "--id" in args:
        k = args.index("--id")
        return len(args) > k + 1 and args[k + 1] == str(agent_id)
    return False


def signal_agent(live, agent_id: int, signal: str = "KILL") -> Signalled:
    """Send `signal` to agent `agent_id`'s process: here by pid, otherwise over zenoh."""
    name = signal_name(signal)
    info = live.info()
    a = info["agents"].get(str(agent_id))
    if a is None:
        raise LiveError(
            f"agent {agent_id} is not in run {info['run']} (ids: {', '.join(sorted(info['agents'], key=int))})"
        )
    st = live.statuses({agent_id}).get(agent_id) if a["alive"] else None
    pid, host = (st or a).get("pid"), (st or a).get("host")
    if pid is None:
        raise LiveError(f"agent {agent_id} has no process (it never joined run {info['run']})")
    here = socket.gethostname()
    local = host == here and looks_like_agent(pid, agent_id)
    if not a["alive"]:
        if host != here:
            raise LiveError(
                f"agent {agent_id} is not live (state {a['state']}); it can only be signalled "
                f"on its own host {host} (kill -{name} {pid})"
            )
        if not local:
            raise LiveError(f"agent {agent_id} is not live (state {a['state']}) and its process (pid {pid}) is gone")
    if local:
        try:
            os.kill(pid, SIGNALS[name])
        except ProcessLookupError:
            raise LiveError(f"agent {agent_id}: no process {pid} on this machine") from None
        except PermissionError:
            raise LiveError(f"agent {agent_id}: not allowed to signal pid {pid}") from None
        how = "sent"
    else:
        if name == "CONT":
            raise LiveError(
                f"agent {agent_id} runs on {host}: SIGCONT cannot be delivered over zenoh "
                f"(a stopped process cannot act on a message); run `kill -CONT {pid}` on {host}"
            )
        live.signal_agent(agent_id, name)
        how = "asked over zenoh to take"
    return Signalled(agent_id, name, pid, host, how, bool(a["alive"]))


def wait_dropped(live, done: Signalled, timeout: float = DROP_DEADLINE) -> int:
    """The tick at which the world dropped the agent `done` signalled; LiveError after `timeout` s."""

    def dropped():
        now = live.info()
        return None if now["agents"][str(done.agent)]["alive"] else now

    now = wait_until(dropped, timeout, 0.02)
    if not now:
        raise LiveError(f"agent {done.agent} is still live in the world {timeout:g} s after SIG{done.signal}")
    return now["tick"]


def _last_line(path: Path) -> str:
    try:
        lines = [ln.strip() for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        return ""
    return lines[-1] if lines else ""


def _new_spec(info: dict, run: str, agent_id: int, given: dict) -> dict:
    """The spec of a new agent from the options given, checked against the run's range for
    added agents and the scenario schema; UsageError naming what is wrong."""
    lo, hi = info.get("added_ids", (None, None))
    if lo is not None and lo > hi:
        raise UsageError(
            f"run {run} has no id left for an added agent (its scenario uses the largest id the wire carries)"
        )
    if lo is not None and not lo <= agent_id <= hi:
        raise UsageError(
            f"--id {agent_id}: agents added to run {run} take ids {lo}..{hi} "
            "(the hub's access rules are made for those ids before the run starts)"
        )
    if info.get("added", 0) >= info.get("max_added", float("inf")):
        raise UsageError(
            f"run {run} has added {info['added']} agents already, its limit (run.max_added_agents in the scenario)"
        )
    # lazy: pydantic and the scenario's models (0.1 s) for a new agent's spec only; other live commands never load them
    from pydantic import ValidationError

    # lazy: (as above)
    from swarm.contracts.scenario import format_validation_error
    from swarm.contracts.scenario_tables import AgentSpec

    spec = {"role": "follower", **given}
    try:
        AgentSpec.model_validate({**spec, "id": agent_id})
    except ValidationError as e:
        msg = format_validation_error(f"agent {agent_id}", e).splitlines()
        raise UsageError(
            f"{msg[0].replace('invalid scenario', 'invalid spec')}: "
            f"{'; '.join(m.strip() for m in msg[1:])} (a new agent needs --x --y --heading --speed)"
        ) from None
    follow = given.get("follow")
    if follow is not None and str(follow) not in info["agents"]:
        raise UsageError(f"--follow {follow}: no agent has that id in run {run}")
    return spec


def spawn_log(info: dict, run: str, agent_id: int) -> Path:
    """Where a spawned agent writes its output: `agent-<id>.log` in the run's own `logs/`
    (beside the agents `swarm up` started) when the world runs on this machine and says
    where its results go (`out` in its info); otherwise a file of its own in the runtime
    dir's `logs/` (a world elsewhere, or one started without --out)."""
    out = info.get("out")
    if isinstance(out, str) and out and info.get("host") == socket.gethostname():
        logs = Path(out) / "logs"
        try:
            logs.mkdir(parents=True, exist_ok=True)
            if os.access(logs, os.W_OK):
                return logs / f"agent-{agent_id}.log"
        except OSError:
            pass
    logs = runtime_dir() / "logs"
    logs.mkdir(mode=0o700, parents=True, exist_ok=True)
    return logs / f"{run}-agent-{agent_id}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.log"


def spawn_agent(
    live, agent_id: int, spec: dict | None = None, trust_law: tuple[str, ...] = (), timeout: float = SPAWN_DEADLINE
) -> Spawned:
    """Start agent `agent_id` on this machine (detached, its output in `spawn_log`) and wait
    until the world shows it live. An id the run knows rejoins if it is not live (no `spec`
    then; a live one is refused at once); a new one joins with `spec` (x, y, heading,
    speed, role, orbit_radius, direction, follow, max_turn_rate)."""
    given = {k: v for k, v in (spec or {}).items() if v is not None}
    info, ref = live.info(), live.ref
    new = None
    known = info["agents"].get(str(agent_id))
    if known is not None:
        if given:
            raise UsageError(
                f"agent {agent_id} is already in run {ref.run}: it rejoins from where it dropped; "
                f"--{'/--'.join(k.replace('_', '-') for k in given)} only apply to a new id"
            )
        if known.get("alive"):
            raise LiveError(
                f"agent {agent_id} is already live in run {ref.run} (pid {known.get('pid')} on "
                f"{known.get('host')}): nothing started"
            )
    else:
        new = _new_spec(info, ref.run, agent_id, given)
    log_path = spawn_log(info, ref.run, agent_id)
    args = [sys.executable, "-m", "swarm.agents.process", str(agent_id), ref.endpoint, ref.run]
    if new is not None:
        args.append(json.dumps(new))
    try:  # the agent connects as itself: the run's own file, or one of agent_id's
        ref.creds.identity(agent_user(agent_id))
    except CredentialsError as e:
        raise UsageError(
            f"swarm spawn needs the run's own credentials (on the run's machine) or a file from "
            f"`swarm credentials --agent {agent_id}`: {e}"
        ) from None
    env = {**os.environ, ENV_TRUSTED_LAWS: with_trusted_laws(list(trust_law))}
    if ref.creds.path is not None:
        env[ENV_CREDENTIALS] = str(Path(ref.creds.path).resolve())
    with open(log_path, "ab") as log:
        proc = subprocess.Popen(
            args,
            stdin=subprocess.DEVNULL,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            close_fds=True,
            env=env,
        )

    def started():
        rc = proc.poll()
        if rc is not None:
            return ("exited", rc)
        try:
            a = live.info()["agents"].get(str(agent_id))
        except NoRunError:  # a read the world missed under load: asked again until the deadline
            return None
        return ("live", 0) if a is not None and a["alive"] and a["pid"] == proc.pid else None

    got = wait_until(started, timeout, 0.05)
    if got and got[0] == "live":
        return Spawned(agent_id, proc.pid, log_path)
    if got:
        why = _last_line(log_path) or "no output"
        raise LiveError(f"agent {agent_id} did not start (exit {got[1]}): {why.removeprefix('swarm agent: ')}")
    proc.terminate()
    try:
        proc.wait(timeout=3)
    except subprocess.TimeoutExpired:
        proc.kill()
    raise LiveError(f"agent {agent_id} (pid {proc.pid}) did not join within {timeout:g} s; stopped it (log {log_path})")
