"""TLS for zenoh tcp links across machines: a certificate pair made for one run.

A hub that listens on `tls/HOST:PORT` needs a server certificate whose subjectAltName
names every address a client will dial; clients need the CA that signed it. Swarm makes a
fresh, self-signed CA per run, signs one server certificate with it and throws the CA
private key away (see `generate_run_certificates`).

The zenoh settings (measured with eclipse-zenoh 1.10.2) live under `transport/link/tls`:
the hub sets `listen_certificate` + `listen_private_key` (paths), a client sets
`root_ca_certificate` (a path) or `root_ca_certificate_base64` (the CA's PEM text, base64:
no file on the client machine). Merge the dicts returned here into the settings of
swarm/contracts/transport.py (`insert_json5(key, json.dumps(value))` per key).
"""

from __future__ import annotations

import base64
import datetime as _dt
import ipaddress
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from swarm.contracts.credentials import Credentials
from swarm.contracts.identities import CredentialsError
from swarm.contracts.runtime_dir import private_dir, write_private

VALID_DAYS = 30
TLS = "transport/link/tls"
_WILDCARDS = {"0.0.0.0", "::", ""}


@dataclass(frozen=True)
class TlsFiles:
    """PEM files of one run: the CA certificate (what clients trust) and the hub's
    certificate and private key (what the hub presents)."""

    ca: Path
    cert: Path
    key: Path


# --- endpoints -----------------------------------------------------------------------


def _address_of(endpoint: str) -> str:
    """`tls/HOST:PORT?meta#config` -> `HOST:PORT` (any `proto/` prefix)."""
    proto, sep, rest = endpoint.partition("/")
    if not sep or not proto:
        raise ValueError(f"not a zenoh locator: {endpoint!r}")
    if proto.startswith("unix"):
        raise ValueError(f"{endpoint!r} has no host (a local socket needs no TLS)")
    return rest.split("#", 1)[0].split("?", 1)[0]


def _split_host(address: str) -> str:
    if address.startswith("["):  # [v6]:port
        host, sep, _ = address[1:].partition("]")
        if not sep:
            raise ValueError(f"unclosed '[' in {address!r}")
        return host.split("%", 1)[0]  # drop a zone id (fe80::1%eth0)
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(f"no :PORT in {address!r}")
    return host


def _local_addresses() -> list[str]:
    """This machine's hostname and the non-loopback addresses the standard library finds."""
    hostname = socket.gethostname()
    found = [hostname]
    fqdn = socket.getfqdn()
    if fqdn and fqdn != hostname and "." in fqdn and fqdn != "localhost":
        found.append(fqdn)
    try:
        infos = socket.getaddrinfo(hostname, None, type=socket.SOCK_STREAM)
    except OSError:
        infos = []
    found += [str(info[4][0]).split("%", 1)[0] for info in infos]
    # The address of the default route (a UDP "connect" sends nothing), which the
    # hostname often does not resolve to (Debian maps it to 127.0.1.1).
    for family, probe in ((socket.AF_INET, "192.0.2.1"), (socket.AF_INET6, "2001:db8::1")):
        try:
            with socket.socket(family, socket.SOCK_DGRAM) as s:
                s.connect((probe, 9))
                found.append(s.getsockname()[0].split("%", 1)[0])
        except OSError:
            pass
    out = []
    for h in found:
        try:
            if ipaddress.ip_address(h).is_loopback:
                continue
        except ValueError:
            pass
        out.append(h)
    return out


def _dedupe(hosts: Any) -> list[str]:
    seen, out = set(), []
    for h in hosts:
        k = h.lower()
        if k not in seen:
            seen.add(k)
            out.append(h)
    return out


def hosts_of_endpoint(endpoint: str) -> list[str]:
    """The names a certificate for `endpoint` must carry.

    `tls/HOST:PORT` or `tls/[V6]:PORT` -> [HOST]; a wildcard listen address (`0.0.0.0`,
    `[::]`) -> this machine's hostname, its non-loopback addresses, and loopback.
    """
    host = _split_host(_address_of(endpoint))
    if host in _WILDCARDS:
        return _dedupe(_local_addresses() + ["localhost", "127.0.0.1", "::1"])
    return [host]


# --- certificates ----------------------------------------------------------------------


def _san_entries(hosts: list[str]) -> Any:
    # lazy: cryptography (30 ms) only where a certificate is read or made, not in every process
    from cryptography import x509

    entries: list[x509.GeneralName] = []
    for h in _dedupe(list(hosts) + ["localhost", "127.0.0.1"]):
        h = h.strip().strip("[]")
        if not h:
            continue
        try:
            entries.append(x509.IPAddress(ipaddress.ip_address(h.split("%", 1)[0])))
        except ValueError:
            entries.append(x509.DNSName(h.lower().rstrip(".")))
    return _dedupe_general(entries)


def _dedupe_general(entries: Any) -> Any:
    seen, out = set(), []
    for e in entries:
        if e not in seen:
            seen.add(e)
            out.append(e)
    return out


def generate_run_certificates(directory: Path, run: str, hosts: list[str], days: int = VALID_DAYS) -> TlsFiles:
    """Make `directory`/ca.pem, cert.pem and key.pem (all 0600) for one run.

    A self-signed CA (ECDSA P-256) signs one server certificate whose subjectAltName holds
    every host (IPs as IPAddress, names as DNSName) plus localhost and 127.0.0.1; both are
    valid from one hour ago (clock skew) for `days` days. The CA private key is never
    written: the one certificate it had to sign is signed, so a copy of the run directory
    cannot mint further certificates that the run's clients would trust. A new run (or new
    hosts) means a new CA, which is the point of a per-run CA.
    """
    # lazy: cryptography (30 ms) only where a certificate is read or made, not in every process
    from cryptography import x509
    from cryptography.hazmat.primitives import hashes, serialization
    from cryptography.hazmat.primitives.asymmetric import ec
    from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

    directory = Path(directory)
    directory.mkdir(mode=0o700, parents=True, exist_ok=True)
    now = _dt.datetime.now(_dt.UTC)
    not_before, not_after = now - _dt.timedelta(hours=1), now + _dt.timedelta(days=days)

    def name(cn: str) -> Any:
        return x509.Name(
            [x509.NameAttribute(NameOID.ORGANIZATION_NAME, "swarm"), x509.NameAttribute(NameOID.COMMON_NAME, cn[:64])]
        )

    ca_key = ec.generate_private_key(ec.SECP256R1())
    ca_name = name(f"swarm run {run} CA")
    ca_ski = x509.SubjectKeyIdentifier.from_public_key(ca_key.public_key())
    ca_cert = (
        x509.CertificateBuilder()
        .subject_name(ca_name)
        .issuer_name(ca_name)
        .public_key(ca_key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(not_before)
        .not_valid_after(not_after)
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(ca_ski, critical=False)
        .sign(ca_key, hashes.SHA256())
    )

    key = ec.generate_private_key(ec.SECP256R1())
    cert = (
        x509.CertificateBuilder()
        .subject_name(name(f"swarm run {run} hub"))
        .issuer_name(ca_name)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(not_before)
        .not_valid_after(not_after)
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH]), critical=False)
        .add_extension(x509.SubjectAlternativeName(_san_entries(hosts)), critical=False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_subject_key_identifier(ca_ski), critical=False)
        .sign(ca_key, hashes.SHA256())
    )
    del ca_key  # deliberately never serialised

    files = TlsFiles(ca=directory / "ca.pem", cert=directory / "cert.pem", key=directory / "key.pem")
    write_private(files.ca, ca_cert.public_bytes(serialization.Encoding.PEM))
    write_private(files.cert, cert.public_bytes(serialization.Encoding.PEM))
    write_private(
        files.key,
        key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()),
    )
    return files


# --- zenoh settings --------------------------------------------------------------------


def hub_tls_settings(files: TlsFiles) -> dict:
    """Keys to merge into the hub's settings (a router listening on `tls/...`)."""
    return {
        f"{TLS}/listen_certificate": str(files.cert),
        f"{TLS}/listen_private_key": str(files.key),
        f"{TLS}/enable_mtls": False,
    }


def client_tls_settings(ca_path: Path) -> dict:
    """Keys to merge into a client's settings (connecting to `tls/HOST:PORT`): trust the
    run's CA only, and check that HOST is in the hub certificate's subjectAltName."""
    return {
        f"{TLS}/root_ca_certificate": str(ca_path),
        f"{TLS}/verify_name_on_connect": True,
        f"{TLS}/enable_mtls": False,
    }


def client_tls_settings_inline(ca_pem: bytes) -> dict:
    """Like `client_tls_settings`, with the CA's PEM text inline (base64 of the PEM bytes),
    so the client machine needs no CA file; e.g. passed in an agent's launch arguments."""
    return {
        f"{TLS}/root_ca_certificate_base64": base64.b64encode(ca_pem).decode("ascii"),
        f"{TLS}/verify_name_on_connect": True,
        f"{TLS}/enable_mtls": False,
    }


# --- a run's certificates, from its endpoint and credentials ---------------------------


def run_tls_dir(directory: Path, run: str) -> Path:
    return Path(directory) / f"{run}.tls"


def run_hub_settings(directory: Path, run: str, listen: str) -> tuple[dict, str]:
    """Certificates for run `run` listening on `listen` (in `<directory>/<run>.tls/`): the
    hub's settings and the CA's PEM text, which goes into the run's credentials."""
    d = run_tls_dir(directory, run)
    files = generate_run_certificates(private_dir(d), run, hosts_of_endpoint(listen))
    return hub_tls_settings(files), files.ca.read_text()


def client_settings_for(creds: Credentials) -> dict:
    """A client's TLS settings from the run's credentials (the CA travels inside them)."""
    if creds.tls_ca is None:
        raise CredentialsError(
            f"the credentials of run {creds.run} carry no TLS certificate authority (its endpoint is {creds.endpoint})"
        )
    return client_tls_settings_inline(creds.tls_ca.encode())
