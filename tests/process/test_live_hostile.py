"""Issue 33 against a real `swarm up` over zenoh (slow): the operator's free text and floods,
and `swarm echo` saying what it cannot give.

One lockstep case 2, tapped from the start by `swarm echo truth --json` and `swarm echo
events --json` (processes). Then: `swarm echo agent/99/cmd` (not in the run, and not an id
it could add) is one line and exit 1; `agent/12/cmd` (an id `swarm spawn` may still add) is
waited for, with a note first; 100 pauses and 100 resumes whose `by` carries terminal escape
sequences, then a stop with a 60 KB reason of the same kind. The run ends as on Ctrl-C; its
record holds a bounded number of pause/resume events (the rest counted in `over_limit`),
ending with the clock's state; the stop's reason is bounded and escaped; no escape sequence
reached `swarm up`'s terminal, the world's log or the taps' output, and no line of its own
(`results: /nonexistent`) was printed; the truth tap ends with the final state decoded
(not malformed), its losses (if any) counted, and every numbered truth message it got,
in order.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest
from runtime_helpers import SCENARIOS, start_up, swarm_cmd, wait_for
from typer.testing import CliRunner

from swarm.api.live import connect
from swarm.cli.main import app
from swarm.contracts import wire
from swarm.contracts.freetext import BY_CHARS
from swarm.contracts.vocabulary import ExitCode
from swarm.live.client import open_run_session
from swarm.world.inbox import ADMIN_BURST, ADMIN_RATE

EVIL = "\x1b[2J\x1b[H\x1b]0;pwned\x07\nresults: /nonexistent\n"
PAIRS = 100  # 200 admin queries: twenty times the budget's burst (ADMIN_BURST 10, then ADMIN_RATE 2 a second)


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def no_controls(text: str, what: str) -> None:
    bad = sorted({repr(ch) for ch in text if not ch.isprintable() and ch not in "\n\t"})
    assert not bad, f"control characters in {what}: {bad}"


def json_lines(text: str) -> list[dict]:
    return [json.loads(ln) for ln in text.splitlines() if ln.startswith("{")]


@pytest.mark.slow
def test_floods_and_escapes_from_the_operator_and_taps_that_say_what_they_miss(rt, tmp_path, monkeypatch):
    monkeypatch.setenv("SWARM_RUNTIME_DIR", rt.dir)
    for var in ("SWARM_CREDENTIALS", "SWARM_RUN", "SWARM_CONNECT"):
        monkeypatch.delenv(var, raising=False)
    out = tmp_path / "run"
    up = start_up(rt.tracker, SCENARIOS / "case2.toml", out, "--clock", "lockstep", "--duration", "3000")
    up.wait_started(120)
    run, _ = up.banner()
    truth = rt.tracker.spawn(swarm_cmd("echo", "truth", "--json"), "echo-truth")
    events = rt.tracker.spawn(swarm_cmd("echo", "events", "--json"), "echo-events")
    wait_for(lambda: '"tick"' in truth.text(), 120, "swarm echo truth to print")

    # an agent the run cannot have: one line, exit 1; one it may still add: a note, then the wait
    res = invoke("echo", "agent/99/cmd")
    assert res.exit_code == ExitCode.FAILED, res.output
    assert (
        res.stderr.strip() == f"agent 99 is not in run {run} (ids: 1, 2, 3, 4, 5, 6; agents added at run time: 7..30)"
    )
    with connect() as live:
        tap = live.echo("agent/12/cmd")
        first = next(tap)
        assert first.note is not None and f"agent 12 is not in run {run} yet" in first.note and not first.is_data
        tap.close()

    # the flood, then the stop with a reason of 60 KB
    with open_run_session() as live:
        t0 = time.monotonic()
        for i in range(PAIRS):
            assert live.admin("pause", by=f"flood {i} {EVIL}")["paused"] is True
            assert live.admin("resume", by=f"flood {i} {EVIL}")["paused"] is False
        elapsed = time.monotonic() - t0
        live.admin("stop", by=EVIL + "x" * 60_000)
    assert up.launcher.wait(180) == ExitCode.INTERRUPTED
    assert truth.wait(120) == ExitCode.OK and events.wait(120) == ExitCode.OK

    # swarm up's terminal and the world's log: no escape sequence, no line of the operator's
    said = up.launcher.text()
    no_controls(said, "swarm up's output")
    assert "results: /nonexistent" not in said.splitlines()
    (stopped,) = [ln for ln in said.splitlines() if "stopped from another terminal" in ln]
    assert "(asked by \\x1b[2J\\x1b[H\\x1b]0;pwned\\x07\\nresults: /nonexistent\\nxxx" in stopped
    assert len(stopped) < BY_CHARS + 150
    no_controls(up.world_text(), "the world's log")

    # the record: pauses and resumes within their budget, the rest counted, the state last
    summary = up.summary()
    assert len(json.dumps(summary)) < 200_000
    told = [e for e in summary["events"] if e["kind"] in ("pause", "resume")]
    assert len(told) <= ADMIN_BURST + ADMIN_RATE * elapsed + 2, (len(told), elapsed)
    assert summary["over_limit"].get("admin", 0) >= 2 * PAIRS - len(told)
    assert told[-1]["kind"] == "resume"
    (stop,) = [e for e in summary["events"] if e["kind"] == "stop"]
    assert len(stop["reason"]) <= BY_CHARS + 40 and stop["reason"].startswith("asked by \\x1b[2J")
    for e in summary["events"]:
        no_controls(e["reason"], f"the {e['kind']} event's reason")

    # the event tap: what it printed is escaped; it saw the stop last
    seen = json_lines(events.text())
    assert seen and seen[-1]["kind"] == "stop" and seen[-1]["reason"] == stop["reason"]
    no_controls(events.text(), "swarm echo events")

    # the truth tap: every line decoded, ticks in order, the final state (u null) last, and
    # what it lost (if anything) counted, with the total at the end
    docs = json_lines(truth.text())
    assert docs and all("error" not in d for d in docs), [d for d in docs if "error" in d][:3]
    ticks = [d["tick"] for d in docs]
    assert ticks == sorted(ticks) and len(set(ticks)) == len(ticks)
    assert all(a["u"] is None for a in docs[-1]["agents"]) and docs[-1]["tick"] == stop["tick"]
    lost = sum(d.get("dropped", 0) for d in docs)
    assert (f"dropped {lost} message" in truth.text()) == (lost > 0)
    assert all(d["key"] == f"swarm/{run}/truth" for d in docs)
    assert wire.truth_key(run) == docs[0]["key"]


def test_echo_of_an_agent_key_needs_no_run_to_refuse_a_bad_id(tmp_path: Path, monkeypatch):
    """A malformed id is still refused before any run is looked for (exit 2)."""
    monkeypatch.setenv("SWARM_RUNTIME_DIR", str(tmp_path))
    res = invoke("echo", "agent/x/cmd")
    assert res.exit_code == ExitCode.USAGE and "'x' is not an agent id" in res.stderr
