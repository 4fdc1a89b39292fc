"""A run's credentials: what a process needs to connect, and the files that carry it.

Every run has a random secret; each identity's password is derived from it
(swarm/contracts/identities.py). The world writes the secret and the endpoint to
`<runtime dir>/<run>.cred` (mode 0600, in a 0700 directory owned by the user:
swarm/contracts/runtime_dir.py). Local processes of that user derive any identity from
it. For another machine, `swarm credentials` exports a file that holds one identity's
password only (and the run's TLS certificate authority, if the run uses TLS): an
agent on that machine can then act as itself and nothing else. A file for an agent host
(`swarm credentials --host NAME --agents 3-5`) holds the `host` identity and the
identities of the agents it runs, and nothing else.

This module only builds, checks, reads, writes and finds those files; zenoh's
configuration from them is swarm/contracts/transport.py and swarm/contracts/access.py.
"""

from __future__ import annotations

import json
import os
import secrets
import stat
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from swarm.contracts import wire
from swarm.contracts.identities import HOST, CredentialsError, agent_user, check_host_name, password_for
from swarm.contracts.runtime_dir import dial_endpoint, pid_alive, read_private, runtime_dir, write_private
from swarm.contracts.runtime_sweep import sweep_stale

ENV_CREDENTIALS = "SWARM_CREDENTIALS"  # path of a credentials file (remote agents, CI)
SUFFIX = ".cred"


def parse_ids(text: str) -> tuple[int, ...]:
    """Agent ids written as `3,4,5`, `3-5` or `1-3,7` (sorted, each once)."""
    out: set[int] = set()
    for part in text.replace(" ", "").split(","):
        lo, sep, hi = part.partition("-")
        try:
            a, b = int(lo), int(hi) if sep else int(lo)
        except ValueError:
            raise CredentialsError(f"agent ids {text!r}: expected e.g. 3,4,5 or 3-5") from None
        if a < 0 or b < a or b - a > 100000:
            raise CredentialsError(f"agent ids {text!r}: {part!r} is not a range of ids")
        out.update(range(a, b + 1))
    return tuple(sorted(out))


@dataclass(frozen=True)
class Credentials:
    """What a process needs to connect to a run. A run's own file has the `secret` (any
    identity can be derived); an exported file has one `user` and its `password`."""

    run: str
    endpoint: str
    secret: str | None = None
    user: str | None = None
    password: str | None = None
    pid: int | None = None  # the world's pid (local runs: is it still there?)
    tls_ca: str | None = None  # PEM of the run's certificate authority (tls/ endpoints)
    hub_is_open: bool = False  # the hub checks nothing (SWARM_OPEN_HUB): connect without an identity
    ids: tuple[int, ...] | None = None  # the scenario's agent ids
    added_ids: tuple[int, int] | None = None  # first and last id an added agent may take
    host: str | None = None  # an agent host's file: the host's name (`user` is then `host`)
    agents: tuple[tuple[int, str], ...] | None = None  # ...and its agents' (id, password)
    path: Path | None = field(default=None, compare=False)

    def check_agent(self, agent_id: int) -> None:
        """CredentialsError unless the hub knows `agent_id` (it refuses any other identity
        at connect, with no reason given, after its connect timeout)."""
        if (
            self.ids is None
            or agent_id in self.ids
            or (self.added_ids is not None and self.added_ids[0] <= agent_id <= self.added_ids[1])
        ):
            return
        added = (
            f"; agents added at run time take ids {self.added_ids[0]}..{self.added_ids[1]}"
            if self.added_ids is not None and self.added_ids[0] <= self.added_ids[1]
            else ""
        )
        raise CredentialsError(
            f"agent {agent_id} is not in scenario of run {self.run} (ids: {', '.join(map(str, self.ids))}{added})"
        )

    def identity(self, user: str) -> tuple[str, str]:
        """(user, password) for `user`, or CredentialsError naming what the file holds."""
        if self.secret is not None:
            return user, password_for(self.secret, self.run, user)
        if self.user == user and self.password is not None:
            return user, self.password
        for aid, password in self.agents or ():
            if agent_user(aid) == user:
                return user, password
        where = f" in {self.path}" if self.path else ""
        held = (
            repr(self.user)
            if not self.agents
            else f"host {self.host!r} and agents {', '.join(str(a) for a, _ in self.agents)}"
        )
        raise CredentialsError(f"the credentials{where} are for {held} of run {self.run}, not {user!r}")

    def export(self, user: str) -> Credentials:
        """A copy that holds only `user`'s password (for another machine; no pid either)."""
        u, p = self.identity(user)
        return replace(self, secret=None, user=u, password=p, pid=None, path=None, host=None, agents=None)

    def export_host(self, name: str, agent_ids: Any) -> Credentials:
        """A copy for agent host `name` running `agent_ids`: the `host` identity (the host
        router's, at the hub) and those agents' identities, nothing else (no secret, no pid)."""
        ids = tuple(sorted(set(agent_ids)))
        if not ids:
            raise CredentialsError("an agent host needs at least one agent id")
        for aid in ids:
            self.check_agent(aid)
        agents = tuple((aid, self.identity(agent_user(aid))[1]) for aid in ids)
        u, p = self.identity(HOST)
        return replace(
            self, secret=None, user=u, password=p, pid=None, path=None, host=check_host_name(name), agents=agents
        )

    def host_agents(self) -> tuple[int, ...] | None:
        """The agent ids an agent host's file holds identities for (None: not such a file)."""
        return None if self.agents is None else tuple(a for a, _ in self.agents)

    def to_json(self) -> dict:
        d = {"v": 1, "run": self.run, "endpoint": self.endpoint}
        for k in ("secret", "user", "password", "pid", "tls_ca"):
            if getattr(self, k) is not None:
                d[k] = getattr(self, k)
        if self.hub_is_open:
            d["open_hub"] = True
        if self.ids is not None:
            d["ids"] = list(self.ids)
        if self.added_ids is not None:
            d["added_ids"] = list(self.added_ids)
        if self.host is not None:
            d["host"] = self.host
        if self.agents is not None:
            d["agents"] = {str(a): p for a, p in self.agents}
        return d


def new_credentials(
    run: str,
    endpoint: str,
    pid: int | None = None,
    tls_ca: str | None = None,
    hub_is_open: bool = False,
    ids: tuple[int, ...] | None = None,
    added_ids: tuple[int, int] | None = None,
) -> Credentials:
    return Credentials(
        wire.check_run_id(run),
        endpoint,
        secret=secrets.token_hex(32),
        pid=pid,
        tls_ca=tls_ca,
        hub_is_open=hub_is_open,
        ids=ids,
        added_ids=added_ids,
    )


def parse(text: str, path: Path | None = None) -> Credentials:
    where = str(path) if path else "credentials"
    try:
        d = json.loads(text)
    except (ValueError, RecursionError) as e:
        raise CredentialsError(f"{where}: not a credentials file ({e})") from None
    if not isinstance(d, dict) or d.get("v") != 1:
        raise CredentialsError(f'{where}: not a swarm credentials file (no "v": 1)')

    def required_field(name: str) -> str:
        v = d.get(name)
        if not isinstance(v, str) or not v:
            raise CredentialsError(f"{where}: {name}: expected a non-empty string")
        return v

    def text_field(name: str) -> str | None:
        return None if d.get(name) is None else required_field(name)

    try:
        run = wire.check_run_id(required_field("run"))
    except wire.WireError as e:
        raise CredentialsError(f"{where}: run: {e}") from None
    secret = text_field("secret")
    if secret is not None:
        try:
            if len(bytes.fromhex(secret)) < 16:
                raise ValueError
        except ValueError:
            raise CredentialsError(f"{where}: secret: expected at least 32 hex digits") from None
    user, password = text_field("user"), text_field("password")
    if secret is None and (user is None or password is None):
        raise CredentialsError(f"{where}: holds neither a secret nor a user and password")
    pid = d.get("pid")
    if pid is not None and (type(pid) is not int or pid <= 0):
        raise CredentialsError(f"{where}: pid: expected a positive integer")
    hub_is_open = d.get("open_hub", False)
    if type(hub_is_open) is not bool:
        raise CredentialsError(f"{where}: open_hub: expected true or false")
    ids, added = d.get("ids"), d.get("added_ids")
    if ids is not None and not (isinstance(ids, list) and all(type(i) is int and i >= 0 for i in ids)):
        raise CredentialsError(f"{where}: ids: expected a list of agent ids")
    if added is not None and not (isinstance(added, list) and len(added) == 2 and all(type(i) is int for i in added)):
        raise CredentialsError(f"{where}: added_ids: expected [first, last]")
    host = text_field("host")
    if host is not None:
        try:
            check_host_name(host)
        except CredentialsError as e:
            raise CredentialsError(f"{where}: host: {e}") from None
    agents = d.get("agents")
    if agents is not None:
        if not (
            isinstance(agents, dict)
            and agents
            and all(
                isinstance(k, str) and k.isascii() and k.isdigit() and k == str(int(k)) and isinstance(v, str) and v
                for k, v in agents.items()
            )
        ):
            raise CredentialsError(f'{where}: agents: expected {{"<id>": "<password>", ...}}')
        agents = tuple(sorted((int(k), v) for k, v in agents.items()))
    if (host is None) != (agents is None):
        raise CredentialsError(f"{where}: an agent host's file has both host and agents")
    return Credentials(
        run,
        required_field("endpoint"),
        secret,
        user,
        password,
        pid,
        text_field("tls_ca"),
        hub_is_open,
        None if ids is None else tuple(ids),
        None if added is None else (added[0], added[1]),
        host,
        agents,
        path,
    )


def read(path: Path) -> Credentials:
    """A credentials file; it must be the user's own and readable by nobody else. A file
    refused for its owner or mode that is no credentials file at all (`--credentials
    /etc/passwd`) is refused as that, not with advice to chmod it."""
    path = Path(path)
    try:
        data = read_private(path)
    except CredentialsError:
        _refuse_if_not_credentials(path)
        raise
    try:
        return parse(data.decode("utf-8"), path)
    except UnicodeDecodeError:
        raise CredentialsError(f"{path}: not a credentials file (not UTF-8)") from None


def _refuse_if_not_credentials(path: Path) -> None:
    """CredentialsError "not a credentials file" if `path`, a regular file that read_private
    refused, does not parse as one; nothing if it does or cannot be read (read_private's
    reason stands). What it reads is only parsed, never used."""
    try:
        if not stat.S_ISREG(os.lstat(path).st_mode):
            return
        with open(path, "rb") as f:
            data = f.read(1 << 20)
    except OSError:
        return
    try:
        parse(data.decode("utf-8"), path)
    except UnicodeDecodeError:
        raise CredentialsError(f"{path}: not a credentials file (not UTF-8)") from None


def write(creds: Credentials, path: Path) -> Path:
    write_private(path, (json.dumps(creds.to_json(), indent=1) + "\n").encode())
    return Path(path)


def run_file(run: str) -> Path:
    try:
        return runtime_dir() / f"{wire.check_run_id(run)}{SUFFIX}"
    except wire.WireError as e:
        raise CredentialsError(str(e)) from None


def local_runs() -> list[Credentials]:
    """The credentials of every local run whose world still exists; the files of those whose
    world is gone are removed on the way (swarm/contracts/runtime_sweep.py)."""
    out = []
    d = runtime_dir()
    sweep_stale(d)
    for p in sorted(d.glob(f"*{SUFFIX}")):
        try:
            c = read(p)
        except CredentialsError:
            continue
        if c.secret is not None and (c.pid is None or pid_alive(c.pid)):
            out.append(c)
    return out


def from_environment() -> Credentials | None:
    """The file named by $SWARM_CREDENTIALS, if set."""
    p = os.environ.get(ENV_CREDENTIALS)
    return read(Path(p)) if p else None


def find_local(run: str | None = None, endpoint: str | None = None) -> Credentials:
    """The own credentials file of a local run (the runtime dir only): run `run`, or the one
    listening on `endpoint`, or the only one. CredentialsError says what was looked at."""
    if run is not None:
        f = run_file(run)
        if f.exists():  # the run id says which; the endpoint may be any way of dialling it
            return read(f)
    dial = None if endpoint is None else dial_endpoint(endpoint)
    found = [c for c in local_runs() if (run is None or c.run == run) and (dial is None or c.endpoint == dial)]
    if len(found) == 1:
        return found[0]
    what = " and ".join(x for x in (f"run {run}" if run else "", f"endpoint {endpoint}" if endpoint else "") if x)
    if not found:
        raise CredentialsError(
            f"no credentials for {what or 'a local run'} in {runtime_dir()} (a run on "
            f"another machine: a file from `swarm credentials` there, with --credentials "
            f"or {ENV_CREDENTIALS})"
        )
    raise CredentialsError(f"{len(found)} local runs match ({', '.join(c.run for c in found)}); pick one with --run")


def find(run: str | None = None, endpoint: str | None = None, path: Path | None = None) -> Credentials:
    """The credentials to use: `path` (--credentials), else $SWARM_CREDENTIALS, else the
    local run's own file (`find_local`)."""
    c = read(path) if path is not None else from_environment()
    if c is not None:
        if run is not None and c.run != run:
            raise CredentialsError(f"{c.path}: credentials of run {c.run}, not of run {run}")
        return c
    return find_local(run, endpoint)


def from_environment_path() -> Path | None:
    p = os.environ.get(ENV_CREDENTIALS)
    return Path(p) if p else None
