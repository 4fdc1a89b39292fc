"""The guard (`swarm robots guard --robots FILE`; docs/guides/robots.md#guard): a process next
to the robots' router, on the robots' machine, that zero-twists a robot whose commands stopped.

It watches every robot's command topic (a zenoh subscriber on the topic's keys, of any type,
with no subscription token: a robot's `cmd_type = "auto"` must not read the guard's) and, when
the last command a robot got was a motion command and no command came for `cmd_timeout` s,
sends that robot zero twists (swarm/robots/halt.py `Halt`, STOP_REPEAT of them), as twist_mux
does with its topic timeout. It sends nothing while commands flow, nor after a zero one (the
world stopped the robot itself), so it never fights the world; its own samples (its GID) are
not commands. One line per stop and per robot that moves again. What it is for: the world's
machine (a laptop on Wi-Fi) losing its link to the robots, or a world killed with no
`swarm up` left to stop the robots.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from swarm.contracts.vocabulary import ExitCode, signal_exit
from swarm.robots.halt import Halt, HaltPlan, Target
from swarm.ros2 import cdr
from swarm.ros2.attachment import parse_attachment
from swarm.ros2.types import TWIST, TWIST_STAMPED

PERIOD = 0.01  # s between the guard's looks at the robots' last commands


@dataclass
class Watched:
    """One robot as the guard sees it: when its last command came (the guard's clock), whether
    it was a motion command, and whether the guard has stopped it since."""

    target: Target
    last_at: float | None = None
    moving: bool = False
    stopped: bool = False  # by the guard, since its last motion command
    stops: int = 0
    commands: int = 0

    def command(self, now: float, vx: float, wz: float) -> bool:
        """A command seen at `now`; True when it moves a robot the guard had stopped."""
        self.last_at, self.commands = now, self.commands + 1
        self.moving = vx != 0.0 or wz != 0.0
        again = self.moving and self.stopped
        if self.moving:
            self.stopped = False
        return again

    def due(self, now: float, timeout: float) -> bool:
        """Whether the robot must be stopped now: moving, and its last command older than `timeout`."""
        return self.moving and not self.stopped and self.last_at is not None and now - self.last_at > timeout


def decode_command(key: str, payload: bytes) -> tuple[float, float] | None:
    """(linear.x, angular.z) of a Twist or TwistStamped sample on `key` (the type is in the
    key); None for another type or a malformed one."""
    parts = key.split("/")
    dds = parts[-2] if len(parts) >= 2 else ""
    try:
        if dds == TWIST.dds:
            return cdr.decode_twist(payload)
        if dds == TWIST_STAMPED.dds:
            return cdr.decode_twist_stamped(payload)[2:]
    except cdr.CdrError:
        return None
    return None


class Guard:
    """The guard of `plan`'s robots: `open()` reaches the router, `step()` stops the robots
    that are due (the main loop calls it every PERIOD s), `close()`. `say(line)` for its lines;
    `clock` monotonic seconds."""

    def __init__(
        self,
        plan: HaltPlan,
        cmd_timeout: float,
        say: Callable[[str], None],
        clock: Callable[[], float] = time.monotonic,
    ):
        self.plan, self.cmd_timeout, self.say, self.clock = plan, cmd_timeout, say, clock
        self.robots = {t.agent: Watched(t) for t in plan.targets}
        self.halt: Halt | None = None
        self.node: Any = None
        self.lock = threading.Lock()
        self.again: list[int] = []  # robots that moved again after a stop (zenoh's thread -> ours)

    def open(self) -> None:
        from swarm.ros2.node import Ros2Node  # lazy: zenoh's native library, once the guard runs

        self.halt = Halt(self.plan, name="swarm_guard")
        try:
            self.node = node = Ros2Node(self.halt.session, "swarm_guard", "", self.plan.domain, self.plan.distro)
            for w in self.robots.values():
                node.listen(w.target.topic, self._on_command(w))
        except BaseException:
            self.close()
            raise

    def plan_targets(self) -> tuple[Target, ...]:
        """The robots, with the command types learned from their subscriptions."""
        return self.halt.plan.targets if self.halt is not None else self.plan.targets

    def _on_command(self, w: Watched) -> Callable[[str, bytes, bytes | None], None]:
        def seen(key: str, payload: bytes, att: bytes | None) -> None:  # zenoh's thread
            now = self.clock()
            halt = self.halt
            if att is not None and halt is not None:
                try:
                    if parse_attachment(att)[2] == halt.gid:
                        return  # our own zero twist
                except ValueError:
                    pass
            twist = decode_command(key, payload)
            if twist is None:
                return
            with self.lock:
                if w.command(now, *twist):
                    self.again.append(w.target.agent)

        return seen

    def step(self) -> None:
        now = self.clock()
        with self.lock:
            due = [w for w in self.robots.values() if w.due(now, self.cmd_timeout)]
            for w in due:
                w.stopped, w.stops = True, w.stops + 1
            again, self.again = self.again, []
        if due and self.halt is not None:
            self.halt.zero(only=[w.target.agent for w in due])
        for w in due:
            self.say(f"guard: {w.target.label()}: no command for {self.cmd_timeout:g} s: zero twist sent")
        for agent in again:
            self.say(f"guard: {self.robots[agent].target.label()}: commands again")

    def run(self, stop: threading.Event, duration: float | None = None) -> None:
        end = None if duration is None else self.clock() + duration
        while not stop.wait(PERIOD):
            self.step()
            if end is not None and self.clock() >= end:
                break

    def close(self) -> None:
        if self.node is not None:
            try:
                self.node.close()
            except Exception:
                pass
            self.node = None
        if self.halt is not None:
            self.halt.close()
            self.halt = None


def run_guard(plan: HaltPlan, cmd_timeout: float, say: Callable[[str], None], duration: float | None = None) -> int:
    """`swarm robots guard`: until Ctrl-C / SIGTERM (exit 130 / 143) or `duration` s (exit 0);
    HaltError (one line) when the router cannot be reached."""
    guard = Guard(plan, cmd_timeout, say)
    stop, caught = threading.Event(), []

    def on_signal(signum: int, _frame: object) -> None:
        caught.append(signum)
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        guard.open()
        types = ", ".join(f"{t.agent} {t.topic} {'/'.join(t.types)}" for t in guard.plan_targets())
        say(
            f"guard: {len(plan.targets)} robots on {plan.connect}, command timeout {cmd_timeout:g} s "
            f"(robots: {types}); Ctrl-C stops it"
        )
        guard.run(stop, duration)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        guard.close()
    stops = sum(w.stops for w in guard.robots.values())
    say(f"guard: ended; it stopped a robot {stops} times")
    return signal_exit(caught[0]) if caught else ExitCode.OK
