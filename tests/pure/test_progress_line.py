"""`swarm up`'s progress line on a terminal (swarm/runtime/progress.py, drawn by rich): one row
kept at the bottom, lines printed meanwhile above it, the last one left in place at the end;
without a terminal, plain lines as before (tests/process/test_messages.py)."""

from __future__ import annotations

import io
import re
import sys

from swarm.runtime.progress import ProgressLine

FIG = {"time": 1.0, "tick": 100, "ticks": 1000, "wall": 1.0, "errors": {1: 0.004, 2: None}, "dropped": []}


def plain(text: str) -> str:
    return re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", text)


def test_on_a_terminal_the_line_stays_below_what_is_printed_meanwhile(monkeypatch):
    out = io.StringIO()
    monkeypatch.setattr(sys, "stdout", out)
    line = ProgressLine(tty=True)
    line.show(FIG)
    print("swarm up: agent 2 (pid 42) exited (exit code 4)")  # the launcher's say(), meanwhile
    line.show({**FIG, "tick": 900, "time": 9.0, "wall": 3.0})
    line.end()
    assert sys.stdout is out  # rich gave stdout back
    text = plain(out.getvalue())
    assert "tick 100/1000" in text and "radial error 1:0.4% 2:-" in text, text
    said = text.index("swarm up: agent 2 (pid 42) exited")
    assert text.rindex("tick 900/1000") > said, text  # drawn again under the launcher's line
    assert text.endswith("\n"), text  # `end` moved past it
    line.end()  # again: nothing


def test_without_a_terminal_plain_lines(capsys):
    line = ProgressLine(tty=False)
    line.show(FIG)
    line.end()
    out = capsys.readouterr().out
    assert out.startswith("t=   1.00s tick 100/1000 ") and "\x1b" not in out and out.count("\n") == 1, out
