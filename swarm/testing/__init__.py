"""Unit-testing a law without a world: `FrameBuilder` makes the observation a law gets (and
the sensor frame an agent gets) from plain keyword arguments, `Neighbour` places another agent,
`FakeWorldLink` runs one agent's brain against a fake world ticked by the test and records the
commands it sends. No zenoh, no processes: a law's test runs in milliseconds.

    from swarm.testing import FakeWorldLink, FrameBuilder, Neighbour

The guide: docs/guides/writing-a-law.md#unit-testing.
"""

from swarm.testing.frames import FrameBuilder, Neighbour
from swarm.testing.link import FakeWorldLink

__all__ = ["FakeWorldLink", "FrameBuilder", "Neighbour"]
