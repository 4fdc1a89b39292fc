"""Credentials files, the runtime directory's checks, identities and the hub's rules
(swarm/contracts/credentials.py, swarm/contracts/access.py, swarm/contracts/laws.py).
No network: the rules themselves are exercised against a real hub in tests/process/test_access.py."""

from __future__ import annotations

import json
import os
import stat

import pytest
from typer.testing import CliRunner

from swarm.cli.main import app
from swarm.contracts import access
from swarm.contracts import credentials as C
from swarm.contracts.laws import LawError, check_trusted, trusted_laws
from swarm.contracts.scenario import parse_scenario
from swarm.contracts.vocabulary import ExitCode
from swarm.world.hub_auth import run_auth

NOBODY = 65534


@pytest.fixture
def rtdir(tmp_path, monkeypatch):
    d = tmp_path / "rt"
    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(d))
    monkeypatch.delenv("SWARM_CREDENTIALS", raising=False)
    return d


@pytest.fixture
def umask0():
    old = os.umask(0)
    try:
        yield
    finally:
        os.umask(old)


def test_passwords_differ_by_user_run_and_secret():
    a = C.new_credentials("r1", "unixsock-stream/x")
    b = C.new_credentials("r1", "unixsock-stream/x")
    pw = a.identity("agent-1")[1]
    assert len(pw) == 32 and pw == a.identity("agent-1")[1]
    assert pw != a.identity("agent-2")[1] and pw != a.identity("operator")[1]
    assert pw != b.identity("agent-1")[1]
    assert pw != C.password_for(a.secret, "r2", "agent-1")


def test_written_files_and_created_dirs_are_private_whatever_the_umask(rtdir, umask0):
    d = C.runtime_dir()
    assert stat.S_IMODE(d.stat().st_mode) == 0o700
    path = C.write(C.new_credentials("r1", "unixsock-stream/x", pid=os.getpid()), C.run_file("r1"))
    assert stat.S_IMODE(path.stat().st_mode) == 0o600
    assert C.read(path).run == "r1"


def test_runtime_dir_open_to_others_is_refused(rtdir):
    rtdir.mkdir(mode=0o700)
    os.chmod(rtdir, 0o777)
    with pytest.raises(C.CredentialsError, match=r"writable by others \(mode 0777\); run `chmod 700"):
        C.runtime_dir()
    os.chmod(rtdir, 0o755)  # readable is fine: every file in it is 0600
    assert C.runtime_dir() == rtdir


@pytest.mark.skipif(os.getuid() != 0, reason="needs root to give a directory away")
def test_runtime_dir_of_another_user_is_refused(rtdir):
    rtdir.mkdir(mode=0o700)
    os.chown(rtdir, NOBODY, NOBODY)
    with pytest.raises(C.CredentialsError, match=f"belongs to uid {NOBODY}, not to you"):
        C.runtime_dir()


def test_runtime_dir_that_is_a_symlink_is_refused(rtdir, tmp_path):
    (tmp_path / "real").mkdir(mode=0o700)
    rtdir.symlink_to(tmp_path / "real")
    with pytest.raises(C.CredentialsError, match="is not a directory"):
        C.runtime_dir()


def test_credentials_readable_by_others_or_foreign_are_refused(rtdir):
    path = C.write(C.new_credentials("r1", "e"), rtdir.parent / "c.cred")
    os.chmod(path, 0o644)
    with pytest.raises(C.CredentialsError, match=r"readable by others \(mode 0644\); run `chmod 600"):
        C.read(path)
    os.chmod(path, 0o600)
    if os.getuid() == 0:
        os.chown(path, NOBODY, NOBODY)
        with pytest.raises(C.CredentialsError, match=f"owned by uid {NOBODY}"):
            C.read(path)


@pytest.mark.parametrize(
    "text,message",
    [
        ("not json", "not a credentials file"),
        ("[]", 'no "v": 1'),
        ('{"v": 1, "endpoint": "e", "secret": "00"}', "run: expected a non-empty string"),
        ('{"v": 1, "run": "a b", "endpoint": "e", "secret": "' + "0" * 64 + '"}', "run:"),
        ('{"v": 1, "run": "r", "endpoint": "e", "secret": "zz"}', "secret: expected at least 32 hex digits"),
        ('{"v": 1, "run": "r", "endpoint": "e"}', "neither a secret nor a user and password"),
        ('{"v": 1, "run": "r", "endpoint": "e", "user": "agent-1", "password": "p", "pid": -1}', "pid:"),
        ('{"v": 1, "run": "r", "endpoint": "e", "user": "agent-1", "password": "p", "open_hub": 1}', "open_hub:"),
        (
            '{"v": 1, "run": "r", "endpoint": "e", "user": "host", "password": "p", '
            '"host": "a/b", "agents": {"1": "p"}}',
            "host: host name",
        ),
        (
            '{"v": 1, "run": "r", "endpoint": "e", "user": "host", "password": "p", '
            '"host": "a", "agents": {"01": "p"}}',
            "agents: expected",
        ),
        (
            '{"v": 1, "run": "r", "endpoint": "e", "user": "host", "password": "p", "host": "a", "agents": []}',
            "agents: expected",
        ),
        ('{"v": 1, "run": "r", "endpoint": "e", "user": "host", "password": "p", "host": "a"}', "both host and agents"),
    ],
)
def test_malformed_credentials_name_the_file_and_field(tmp_path, text, message):
    path = tmp_path / "bad.cred"
    C.write_private(path, text.encode())
    with pytest.raises(C.CredentialsError) as exc:
        C.read(path)
    assert str(path) in str(exc.value) and message in str(exc.value)


def test_an_exported_identity_holds_that_identity_only(rtdir):
    own = C.new_credentials("r1", "tcp/0.0.0.0:7447", pid=1)
    exp = own.export("agent-3")
    doc = exp.to_json()
    assert "secret" not in doc and doc["user"] == "agent-3"
    assert exp.identity("agent-3") == own.identity("agent-3")
    with pytest.raises(C.CredentialsError, match="are for 'agent-3' of run r1, not 'agent-4'"):
        exp.identity("agent-4")
    with pytest.raises(C.CredentialsError):
        exp.identity("operator")
    back = C.parse(json.dumps(doc))
    assert back.identity("agent-3") == own.identity("agent-3")


def test_an_agent_hosts_file_holds_the_host_and_its_agents_only(rtdir):
    own = C.new_credentials("r1", "tls/10.0.0.5:7447", pid=1, tls_ca="PEM", ids=(1, 2, 3, 4), added_ids=(5, 8))
    h = own.export_host("a", [3, 1, 3])
    doc = h.to_json()
    assert "secret" not in doc and "pid" not in doc and doc["user"] == "host" and doc["host"] == "a"
    assert doc["agents"] == {"1": own.identity("agent-1")[1], "3": own.identity("agent-3")[1]}
    assert doc["tls_ca"] == "PEM" and doc["ids"] == [1, 2, 3, 4]
    back = C.parse(json.dumps(doc))
    assert back == h and back.host_agents() == (1, 3)
    assert back.identity("host") == own.identity("host") and back.identity("agent-3") == own.identity("agent-3")
    for user in ("agent-2", "operator", "world"):
        with pytest.raises(C.CredentialsError, match="are for host 'a' and agents 1, 3 of run r1"):
            back.identity(user)
    one = back.export("agent-3")  # what `swarm host` gives agent 3's process: agent 3 only
    assert one.to_json().keys() == {"v", "run", "endpoint", "user", "password", "tls_ca", "ids", "added_ids"}
    assert one.identity("agent-3") == own.identity("agent-3") and one.host_agents() is None
    with pytest.raises(C.CredentialsError, match="agent 9 is not in scenario"):
        own.export_host("a", [9])
    with pytest.raises(C.CredentialsError, match="host name"):
        own.export_host("a b", [1])
    with pytest.raises(C.CredentialsError, match="at least one agent"):
        own.export_host("a", [])


@pytest.mark.parametrize(
    "text,ids", [("3", (3,)), ("3,4,5", (3, 4, 5)), ("3-5", (3, 4, 5)), ("1-3, 7,2", (1, 2, 3, 7))]
)
def test_agent_ids_as_written_on_the_command_line(text, ids):
    assert C.parse_ids(text) == ids


@pytest.mark.parametrize("text", ["", "a", "5-3", "-1", "1-", "1,,2"])
def test_agent_ids_that_are_not(text):
    with pytest.raises(C.CredentialsError, match="agent ids"):
        C.parse_ids(text)


def test_find_prefers_the_given_file_then_the_environment_then_the_run_file(rtdir, tmp_path, monkeypatch):
    mine = C.write(C.new_credentials("r1", "unixsock-stream/a", pid=os.getpid()), C.run_file("r1"))
    other = C.write(C.new_credentials("r2", "unixsock-stream/b", pid=os.getpid()), C.run_file("r2"))
    assert C.find("r1").path == mine
    assert C.find(endpoint="unixsock-stream/b").path == other
    with pytest.raises(C.CredentialsError, match="2 local runs match"):
        C.find()
    monkeypatch.setenv("SWARM_CREDENTIALS", str(other))
    assert C.find().run == "r2"
    with pytest.raises(C.CredentialsError, match="credentials of run r2, not of run r1"):
        C.find("r1")
    assert C.find(path=mine).run == "r1"


def test_stale_run_files_are_not_local_runs(rtdir):
    C.write(C.new_credentials("gone", "unixsock-stream/g", pid=2**22 + 12345), C.run_file("gone"))
    assert C.local_runs() == []
    with pytest.raises(C.CredentialsError, match="no credentials for a local run"):
        C.find()


def test_each_agent_rule_names_only_its_own_keys():
    acl = access.access_control("r1", [1, 2, 30])
    assert acl["default_permission"] == "deny" and acl["enabled"]
    by_id = {r["id"]: r for r in acl["rules"]}
    for pol in acl["policies"]:
        for subject in pol["subjects"]:
            if not subject.startswith("agent-"):
                continue
            k = subject.removeprefix("agent-")
            for rid in pol["rules"]:
                r = by_id[rid]
                if r["flows"] == ["egress"]:
                    continue
                for key in r["key_exprs"]:
                    assert f"/agent/{k}/" in key or key in ("swarm/r1/world/control", "swarm/r1/world/alive"), (k, key)
                    assert "*" not in key
                if "put" in r["messages"]:
                    assert all(key.endswith(("/cmd", "/status")) for key in r["key_exprs"])


def test_the_operator_reads_and_asks_but_forges_nothing():
    rules = access.operator_rules("r1")
    puts = [k for r in rules if "put" in r["messages"] for k in r["key_exprs"]]
    assert puts == ["swarm/r1/agent/*/ctl"]
    for r in rules:
        assert not {"declare_queryable", "reply", "liveliness_token", "delete"} & set(r["messages"])
    queries = [k for r in rules if "query" in r["messages"] for k in r["key_exprs"]]
    assert "swarm/r1/world/admin" in queries and not any(k.endswith("/join") for k in queries)


def test_user_dictionary_has_every_identity_once():
    lines = access.user_dictionary("00" * 32, "r1", [1, 2]).splitlines()
    assert [line.split(":")[0] for line in lines] == ["operator", "agent-1", "agent-2"]
    lines = access.user_dictionary("00" * 32, "r1", [1, 2], host=True).splitlines()
    assert [line.split(":")[0] for line in lines] == ["operator", "agent-1", "agent-2", "host"]


def test_the_host_may_do_what_any_agent_may_and_nothing_else():
    acl = access.access_control("r1", [1, 2], host=True)
    by_subject = {}
    for pol in acl["policies"]:
        for subject in pol["subjects"]:
            by_subject.setdefault(subject, set()).update(pol["rules"])
    agents = by_subject["agent-1"] | by_subject["agent-2"]
    assert by_subject["host"] == agents  # the union of the agents' rules (egress included)
    assert not by_subject["host"] & {r["id"] for r in access.operator_rules("r1")}


def test_a_host_router_confines_its_agents_and_lets_its_hub_through():
    acl = access.host_router_access("r1", [3, 4], "abc123")
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert set(subjects) == {"agent-3", "agent-4", "hub"} and subjects["hub"] == {"id": "hub", "zids": ["abc123"]}
    assert acl["default_permission"] == "deny"
    rules = {r["id"]: r for r in acl["rules"]}
    up = [p for p in acl["policies"] if p["subjects"] == ["hub"]]
    assert [p["rules"] for p in up] == [["upstream"]]
    assert rules["upstream"]["key_exprs"] == ["swarm/r1/**"] and rules["upstream"]["flows"] == ["ingress", "egress"]
    assert access.host_dictionary([("agent-3", "p3"), ("agent-4", "p4")]) == "agent-3:p3\nagent-4:p4\n"


def test_only_built_in_or_trusted_laws(monkeypatch):
    monkeypatch.delenv("SWARM_TRUSTED_LAWS", raising=False)
    check_trusted("bearing", trusted_laws())
    with pytest.raises(LawError, match="--trust-law pkg.mod:f"):
        check_trusted("pkg.mod:f", trusted_laws())
    check_trusted("pkg.mod:f", trusted_laws(["pkg.mod:f"]))
    monkeypatch.setenv("SWARM_TRUSTED_LAWS", "a:b, pkg.mod:f")
    check_trusted("pkg.mod:f", trusted_laws())
    with pytest.raises(LawError):
        check_trusted("pkg.mod:g", trusted_laws())


def test_an_agent_the_hub_does_not_know_is_refused_before_connecting():
    c = C.new_credentials("r1", "e", ids=(1, 2, 3), added_ids=(4, 15))
    for aid in (1, 3, 4, 15):
        c.check_agent(aid)
    with pytest.raises(
        C.CredentialsError,
        match=r"agent 99 is not in scenario of run r1 \(ids: 1, 2, 3; "
        r"agents added at run time take ids 4..15\)",
    ):
        c.check_agent(99)
    assert C.parse(json.dumps(c.to_json())).added_ids == (4, 15)


def _cli(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.mark.slow
def test_swarm_credentials_exports_one_identity_or_says_why_not(rtdir, tmp_path, monkeypatch):
    C.write(
        C.new_credentials("r1", "unixsock-stream/x.sock", pid=os.getpid(), ids=(1, 2), added_ids=(3, 10)),
        C.run_file("r1"),
    )
    out = tmp_path / "a2.cred"
    res = _cli("credentials", "--agent", "2")
    assert res.exit_code == ExitCode.USAGE and "from this machine only: give --endpoint" in res.output
    res = _cli("credentials", "--agent", "2", "--endpoint", "tcp/10.0.0.5:7447", "-o", out)
    assert res.exit_code == ExitCode.OK, res.output
    doc = json.loads(out.read_text())
    assert (doc["user"], doc["endpoint"], "secret" in doc) == ("agent-2", "tcp/10.0.0.5:7447", False)
    assert stat.S_IMODE(out.stat().st_mode) == 0o600
    assert _cli("credentials", "--agent", "2", "--endpoint", "tcp/h:1", "-o", out).exit_code == ExitCode.USAGE  # exists
    for args, what in [
        ((), "give one of --agent ID, --operator or --host NAME --agents IDS"),
        (("--agent", "1", "--operator"), "give one of"),
        (("--host", "a", "--agent", "1"), "give one of"),
        (("--host", "a"), "--host NAME goes with --agents IDS"),
        (("--agents", "1-2", "--operator"), "--host NAME goes with --agents IDS"),
        (("--host", "a", "--agents", "1-99", "--endpoint", "tcp/h:1"), "agent 11 is not in scenario"),
        (("--host", "a b", "--agents", "1", "--endpoint", "tcp/h:1"), "host name"),
        (("--host", "a", "--agents", "x", "--endpoint", "tcp/h:1"), "agent ids"),
        (("--host", "a", "--agents", "1-2"), "from this machine only: give --endpoint"),
        (("--agent", "99", "--endpoint", "tcp/h:1"), "agent 99 is not in scenario of run r1"),
        (("--operator", "--run", "a/b"), "run id"),
        (("--operator", "--run", "r9"), "no credentials for run r9"),
    ]:
        res = _cli("credentials", *args)
        assert res.exit_code == ExitCode.USAGE and what in res.output and "Traceback" not in res.output, (
            args,
            res.output,
        )
    res = _cli(
        "credentials", "--host", "a", "--agents", "1-2,4", "--endpoint", "tls/10.0.0.5:7447", "-o", tmp_path / "a.cred"
    )
    assert res.exit_code == ExitCode.OK, res.output
    assert "host a with agents 1, 2, 4 of run r1" in res.output and "swarm host --credentials a.cred" in res.output
    doc = json.loads((tmp_path / "a.cred").read_text())
    assert (doc["user"], doc["host"], sorted(doc["agents"]), "secret" in doc) == ("host", "a", ["1", "2", "4"], False)
    assert stat.S_IMODE((tmp_path / "a.cred").stat().st_mode) == 0o600
    # $SWARM_CREDENTIALS (an exported file) does not change which file is exported from
    monkeypatch.setenv("SWARM_CREDENTIALS", str(out))
    res = _cli("credentials", "--operator", "--endpoint", "tcp/h:1", "-o", tmp_path / "op.cred")
    assert res.exit_code == ExitCode.OK, res.output
    assert json.loads((tmp_path / "op.cred").read_text())["user"] == "operator"


def test_a_world_that_comes_back_keeps_its_runs_secret(rtdir, monkeypatch):
    """--wait-world: agents of a run whose world was killed get back in with the credentials
    they have; a world of the same run that still lives is not replaced."""

    monkeypatch.delenv("SWARM_OPEN_HUB", raising=False)
    s = parse_scenario(
        {
            "gains": {"c1": 1.0, "c2": 0.5},
            "agents": [
                {"id": 1, "role": "leader", "x": 1.0, "y": 0.0, "heading": 0.0, "speed": 1.0, "orbit_radius": 1.0}
            ],
        }
    )
    dead = C.new_credentials("r1", "unixsock-stream/x", pid=2**22 + 12345)
    C.write(dead, C.run_file("r1"))
    auth = run_auth("r1", "unixsock-stream/x", s)
    assert auth.creds.secret == dead.secret and auth.creds.pid == os.getpid()
    assert C.read(C.run_file("r1")).identity("agent-1") == dead.identity("agent-1")
    C.write(C.new_credentials("r2", "unixsock-stream/y", pid=os.getppid()), C.run_file("r2"))
    with pytest.raises(C.CredentialsError, match=f"run r2 is already running \\(world pid {os.getppid()}\\)"):
        run_auth("r2", "unixsock-stream/y", s)
    fresh = run_auth("r3", "unixsock-stream/z", s)
    assert fresh.creds.secret not in (dead.secret, None)
