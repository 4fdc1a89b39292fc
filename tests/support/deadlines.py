"""How long the tests wait, in one place (docs/testing.md#deadlines).

`DEADLINE` bounds every wait of a test on a process or on the bus (a process to start, to
answer, to exit; the world to listen, to tick, to end; a stop to be heard): it is how long
before a wait is a hang, not how long the thing should take. A wait ends as soon as its
condition holds, so a long bound costs nothing on a fast machine; on a loaded one (short
bounds failed tests at load averages of 11-62 on 2 cores) it is what keeps a slow start a
pass. A test whose point is speed is a benchmark (benchmarks/), not a test. SWARM_TEST_DEADLINE (s) raises it
for a slower machine still, and pytest's limit per test (pyproject `timeout` = 300 s, 2.5 x
the default, or a test's own marker) grows with it in the same ratio (tests/conftest.py), so
that a hang is reported by the wait that hung, with what it waited for.
"""

from __future__ import annotations

import os

DEFAULT = 120.0
DEADLINE = float(os.environ.get("SWARM_TEST_DEADLINE", DEFAULT))
