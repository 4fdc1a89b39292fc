"""Endpoints as the command line takes them (`--connect`, `--listen`, `--endpoint`), checked
before anything dials or binds them, so that a bad one is one line, "not an endpoint: ...",
instead of a zenoh error, a traceback (a port past 65535 overflowed in zenoh's Python
binding) or a misleading "no credentials for endpoint ...".

An endpoint is a zenoh locator of one of the kinds this runtime uses:

    tcp/HOST:PORT            HOST a name, an IPv4 address or [an IPv6 address]
    tls/HOST:PORT            as tcp/
    unixsock-stream/PATH     PATH a file path (absolute on these machines: //tmp/...)

PORT is 1..65535 (0 too for a listening endpoint: the system picks one). zenoh's `#...`
(configuration) and `?...` (metadata) suffixes are allowed after the address. Nothing here
resolves a name or touches the network.
"""

from __future__ import annotations

import re

from swarm.contracts.vocabulary import Coded, ExitCode

KINDS = ("tcp", "tls", "unixsock-stream")
FORMS = "tcp/HOST:PORT, tls/HOST:PORT or unixsock-stream/PATH"
_HOST = re.compile(r"^(\[[0-9A-Fa-f:.%\w]+\]|[A-Za-z0-9._-]+)$")


class EndpointError(Coded, ValueError):
    """A string that is not an endpoint; the message is one line naming it and why."""

    exit_code = ExitCode.USAGE


def check_endpoint(endpoint: str, listen: bool = False, what: str = "") -> str:
    """`endpoint` as it is if it is one (see the module docstring), else EndpointError:
    "not an endpoint: 'foo/bar' (...)", `what` ("--connect") put first when given. `listen`:
    port 0 (any free port) is allowed."""

    def bad(why: str) -> EndpointError:
        lead = f"{what}: " if what else ""
        return EndpointError(f"{lead}not an endpoint: {endpoint!r} ({why})")

    if not isinstance(endpoint, str) or not endpoint.strip():
        raise bad(f"empty; use {FORMS}")
    kind, sep, rest = endpoint.partition("/")
    if not sep or kind not in KINDS:
        raise bad(f"use {FORMS}")
    address = re.split(r"[#?]", rest, maxsplit=1)[0]
    if kind == "unixsock-stream":
        if not address:
            raise bad("no socket path after unixsock-stream/")
        return endpoint
    host, colon, port = address.rpartition(":")
    if not colon:
        raise bad(f"no port: use {kind}/HOST:PORT")
    if not host:
        raise bad(f"no host: use {kind}/HOST:PORT")
    if not _HOST.match(host) or (":" in host and not host.startswith("[")):
        raise bad(f"host {host!r} is not a name or an address; an IPv6 address goes in brackets, [::1]")
    if not re.fullmatch(r"[0-9]{1,9}", port):
        raise bad(f"port {port!r} is not a number")
    low = 0 if listen else 1
    if not low <= int(port) <= 65535:
        raise bad(f"port {int(port)} is not in {low}..65535")
    return endpoint
