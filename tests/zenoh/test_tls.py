"""TLS on zenoh tcp links (swarm/contracts/tls.py), with real sessions on loopback: a
router listening on `tls/127.0.0.1:PORT` with a run's generated certificate; clients that
trust the run's CA get through, clients with another run's CA, plain tcp, or a wrong
password (usrpwd over TLS) are refused at open."""

from __future__ import annotations

import ipaddress
import json
import os
import queue
import socket
import stat
import time

import pytest
import zenoh
from cryptography import x509

from swarm.contracts import tls

OPEN_MS = 5000  # a client that should get in
REFUSE_MS = 1000  # a client that should not: zenoh retries until connect/timeout_ms
RUN = "tls-test"


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def _config(settings: dict):
    cfg = zenoh.Config()
    for key, value in settings.items():
        cfg.insert_json5(key, json.dumps(value))
    return cfg


def open_router(listen: str, extra: dict):
    return zenoh.open(
        _config(
            {
                "mode": "router",
                "listen/endpoints": [listen],
                "scouting/multicast/enabled": False,
                "scouting/delay": 0,
                "transport/shared_memory/enabled": False,
                **extra,
            }
        )
    )


def open_client(connect: str, extra: dict, timeout_ms: int = OPEN_MS):
    return zenoh.open(
        _config(
            {
                "mode": "client",
                "connect/endpoints": [connect],
                "connect/timeout_ms": timeout_ms,
                "scouting/multicast/enabled": False,
                "transport/shared_memory/enabled": False,
                **extra,
            }
        )
    )


def assert_refused(connect: str, extra: dict):
    with pytest.raises(zenoh.ZError):
        s = open_client(connect, extra, timeout_ms=REFUSE_MS)
        s.close()


@pytest.fixture(scope="module")
def certs(tmp_path_factory):
    d = tmp_path_factory.mktemp("tls")
    return (
        tls.generate_run_certificates(d / "run", RUN, ["127.0.0.1"]),
        tls.generate_run_certificates(d / "other", "other-run", ["127.0.0.1"]),
    )


@pytest.fixture(scope="module")
def hub(certs):
    files, _ = certs
    ep = f"tls/127.0.0.1:{free_port()}"
    h = open_router(ep, tls.hub_tls_settings(files))
    try:
        yield h, ep
    finally:
        h.close()


def round_trip(hub_session, client_session, key: str = "swarm/tls-test/ping") -> bytes:
    got: queue.Queue = queue.Queue()
    sub = hub_session.declare_subscriber(key, lambda s: got.put(s.payload.to_bytes()))
    try:
        deadline = time.monotonic() + 5
        while time.monotonic() < deadline:  # put again until the subscription reached the client
            client_session.put(key, b"hello over tls")
            try:
                return got.get(timeout=0.05)
            except queue.Empty:
                pass
        pytest.fail("no put reached the hub within 5 s")
    finally:
        sub.undeclare()


# --- certificates ----------------------------------------------------------------------


def test_files_are_0600_whatever_the_umask_and_the_ca_key_is_not_kept(tmp_path):
    d = tmp_path / "certs"
    d.mkdir()
    (d / "key.pem").write_text("old")
    os.chmod(d / "key.pem", 0o644)
    old = os.umask(0)
    try:
        files = tls.generate_run_certificates(d, RUN, ["10.0.0.5"])
    finally:
        os.umask(old)
    for p in (files.ca, files.cert, files.key):
        assert stat.S_IMODE(p.stat().st_mode) == 0o600, p
    assert sorted(p.name for p in d.iterdir()) == ["ca.pem", "cert.pem", "key.pem"]
    assert b"PRIVATE KEY" not in files.ca.read_bytes() + files.cert.read_bytes()
    assert b"PRIVATE KEY" in files.key.read_bytes()


def test_the_hub_certificate_names_every_host_and_is_signed_by_the_run_ca(tmp_path):
    files = tls.generate_run_certificates(tmp_path, RUN, ["192.168.1.20", "hub.lan", "fd00::2"])
    ca = x509.load_pem_x509_certificate(files.ca.read_bytes())
    cert = x509.load_pem_x509_certificate(files.cert.read_bytes())
    assert ca.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    assert not cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca
    cert.verify_directly_issued_by(ca)
    san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert set(san.get_values_for_type(x509.IPAddress)) == {
        ipaddress.ip_address(a) for a in ("192.168.1.20", "fd00::2", "127.0.0.1")
    }
    assert set(san.get_values_for_type(x509.DNSName)) == {"hub.lan", "localhost"}
    days = (cert.not_valid_after_utc - cert.not_valid_before_utc).days
    assert 29 <= days <= 31


def test_hosts_of_an_endpoint():
    assert tls.hosts_of_endpoint("tls/127.0.0.1:7447") == ["127.0.0.1"]
    assert tls.hosts_of_endpoint("tls/[::1]:7447") == ["::1"]
    assert tls.hosts_of_endpoint("tls/hub.lan:7447?prio=1#iface=eth0") == ["hub.lan"]
    for wildcard in ("tls/0.0.0.0:7447", "tls/[::]:7447"):
        hosts = tls.hosts_of_endpoint(wildcard)
        assert socket.gethostname() in hosts
        assert {"localhost", "127.0.0.1"} <= set(hosts)
        assert len(hosts) == len(set(hosts))
    for bad in ("unixsock-stream//tmp/x.sock", "tls/hub.lan", "hub.lan:7447"):
        with pytest.raises(ValueError):
            tls.hosts_of_endpoint(bad)


# --- zenoh sessions --------------------------------------------------------------------


def test_a_client_trusting_the_run_ca_round_trips_a_put(hub, certs):
    h, ep = hub
    c = open_client(ep, tls.client_tls_settings(certs[0].ca))
    try:
        assert h.info.zid() in c.info.routers_zid()
        assert round_trip(h, c) == b"hello over tls"
    finally:
        c.close()


def test_the_ca_can_be_given_inline_as_base64(hub, certs):
    # Proof that the inline CA is used: the default roots (webpki) do not trust the run's CA.
    h, ep = hub
    c = open_client(ep, tls.client_tls_settings_inline(certs[0].ca.read_bytes()))
    try:
        assert round_trip(h, c) == b"hello over tls"
    finally:
        c.close()


@pytest.mark.slow  # waits out a connect timeout (REFUSE_MS)
def test_a_client_trusting_another_runs_ca_is_refused(hub, certs):
    _, ep = hub
    assert_refused(ep, tls.client_tls_settings(certs[1].ca))


@pytest.mark.slow  # waits out a connect timeout (REFUSE_MS)
def test_plain_tcp_to_the_tls_port_is_refused(hub):
    _, ep = hub
    assert_refused(ep.replace("tls/", "tcp/", 1), {})


@pytest.mark.slow  # waits out a connect timeout (REFUSE_MS)
def test_a_host_missing_from_the_certificate_is_refused_unless_names_are_not_verified(certs):
    files, _ = certs  # names 127.0.0.1 and localhost, not 127.0.0.2
    try:
        port = free_port("127.0.0.2")
    except OSError:
        pytest.skip("no 127.0.0.2 loopback alias on this system")
    ep = f"tls/127.0.0.2:{port}"
    h = open_router(ep, tls.hub_tls_settings(files))
    try:
        assert_refused(ep, tls.client_tls_settings(files.ca))
        lax = {**tls.client_tls_settings(files.ca), "transport/link/tls/verify_name_on_connect": False}
        open_client(ep, lax).close()
    finally:
        h.close()


@pytest.mark.slow  # waits out a connect timeout (REFUSE_MS)
def test_username_and_password_over_tls(certs, tmp_path):
    files, _ = certs
    users = tmp_path / "users.txt"
    users.write_text("agent:s3cret\nworld:other\n")
    ep = f"tls/127.0.0.1:{free_port()}"
    h = open_router(
        ep,
        {
            **tls.hub_tls_settings(files),
            "transport/auth/usrpwd": {"user": "hub", "password": "hubpw", "dictionary_file": str(users)},
        },
    )
    try:
        ca = tls.client_tls_settings(files.ca)
        c = open_client(ep, {**ca, "transport/auth/usrpwd": {"user": "agent", "password": "s3cret"}})
        try:
            assert round_trip(h, c) == b"hello over tls"
        finally:
            c.close()
        assert_refused(ep, {**ca, "transport/auth/usrpwd": {"user": "agent", "password": "wrong"}})
    finally:
        h.close()
