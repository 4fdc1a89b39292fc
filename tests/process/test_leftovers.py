"""The leftover check of the process tests (tests/support/runtime_helpers.py `Runtime`, the `rt`
fixture): a process that is still exiting when a test ends is waited for (a loaded machine
makes exits slow), a process that stays is a leftover and fails the test, and after a failing
test everything is killed at once."""

from __future__ import annotations

import sys

import psutil
import pytest
import runtime_helpers
from runtime_helpers import Runtime

pytestmark = pytest.mark.process

SLOW_EXIT = "import time; time.sleep(1.5)"  # a process still exiting as the test ends


@pytest.mark.slow
def test_a_process_still_exiting_is_waited_for(tmp_path):
    with Runtime(tmp_path) as r:
        p = r.tracker.spawn([sys.executable, "-c", SLOW_EXIT], "slow")
    assert p.poll() == 0  # it was let finish, not killed


@pytest.mark.slow
def test_a_process_that_stays_is_a_leftover(tmp_path, monkeypatch):
    monkeypatch.setattr(runtime_helpers, "DEADLINE", 1.0)  # (a real leftover is waited for DEADLINE s)
    with pytest.raises(AssertionError, match="processes left alive after the test"):
        with Runtime(tmp_path) as r:
            p = r.tracker.spawn([sys.executable, "-c", "import time; time.sleep(600)"], "stays")
    assert not psutil.pid_exists(p.pid) or psutil.Process(p.pid).status() == psutil.STATUS_ZOMBIE


def test_after_a_failing_test_everything_is_killed_at_once(tmp_path):
    with pytest.raises(RuntimeError, match="the test failed"):
        with Runtime(tmp_path) as r:
            p = r.tracker.spawn([sys.executable, "-c", "import time; time.sleep(600)"], "stays")
            raise RuntimeError("the test failed")
    assert p.poll() is not None  # killed and reaped (not waited for: it would have run 600 s)
