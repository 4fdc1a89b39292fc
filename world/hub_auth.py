"""Who may connect to a world: the run's credentials, made when the world starts and
removed when it ends, and the hub's rules built from them.

The world writes `<runtime dir>/<run>.cred` (mode 0600: the run's secret, endpoint, its
pid, the agent ids the hub knows and, for a `tls/` endpoint, the certificate authority
made for the run). Every local process of the same user finds it there; other machines
get one identity each from `swarm credentials` (swarm/cli/access.py).
"""

from __future__ import annotations

import logging
import os
import shutil
from dataclasses import replace

from swarm.contracts import credentials, tls
from swarm.contracts.identities import ENV_SUPERVISOR, CredentialsError
from swarm.contracts.runtime_dir import pid_alive
from swarm.contracts.scenario import Scenario
from swarm.contracts.transport import HubAuth, dial_endpoint, open_hub_requested, runtime_dir

log = logging.getLogger(__name__)


def run_auth(run: str, listen: str, scenario: Scenario) -> HubAuth | None:
    """Write the run's credentials; return the hub's rules (None for an open hub:
    SWARM_OPEN_HUB=1). CredentialsError, one line, when the run cannot be made private or
    its world is still running. A world that comes back after its run's world died keeps
    that run's secret (not its TLS authority, which is made anew)."""
    path = credentials.run_file(run)
    old = credentials.read(path) if path.exists() else None
    if old is not None and old.pid is not None and old.pid != os.getpid() and pid_alive(old.pid):
        raise CredentialsError(f"run {run} is already running (world pid {old.pid})")
    tls_settings, ca = None, None
    if listen.startswith("tls/"):
        try:
            tls_settings, ca = tls.run_hub_settings(runtime_dir(), run, listen)
        except ValueError as e:
            raise CredentialsError(f"{listen}: {e}") from None
    open_hub = open_hub_requested()
    added = scenario.added_id_range
    # local processes dial the endpoint as written in the file (a wildcard as 127.0.0.1)
    creds = credentials.new_credentials(
        run,
        dial_endpoint(listen),
        pid=os.getpid(),
        tls_ca=ca,
        hub_is_open=open_hub,
        ids=tuple(scenario.ids),
        added_ids=(added.start, added.stop - 1),
    )
    if old is not None and old.secret is not None:
        # The file of a world of this run that died (killed: it had no time to remove it):
        # its secret is kept, so that agents waiting for the world (--wait-world) get back in.
        creds = replace(creds, secret=old.secret)
    credentials.write(creds, path)
    if open_hub:
        log.warning("SWARM_OPEN_HUB is set: anyone who reaches the endpoint can act on this run")
        return None
    # The launcher's own password (swarm/contracts/access.py, `supervisor`): taken out of the
    # environment at once; a world started by hand has no supervisor.
    supervisor = os.environ.pop(ENV_SUPERVISOR, "") or None
    return HubAuth(creds, tuple(scenario.ids) + tuple(added), tls_settings, supervisor)


def forget_run(run: str, listen: str) -> None:
    """The run has ended: its credentials (and certificates) go with it; those of another
    world with the same run id (refused by `run_auth`) stay."""
    try:
        d = runtime_dir()
        path = d / f"{run}{credentials.SUFFIX}"
        if path.exists() and credentials.read(path).pid not in (None, os.getpid()):
            return
    except CredentialsError:
        return
    path.unlink(missing_ok=True)
    if listen.startswith("tls/"):
        shutil.rmtree(tls.run_tls_dir(d, run), ignore_errors=True)
