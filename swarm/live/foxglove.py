"""`swarm watch --foxglove`: an observer of a live run that serves it over Foxglove's WebSocket
protocol, with the topics and schemas of the world's own live view (`swarm up --foxglove`,
world/live_view.py), built by the same functions (world/scene.py's `SceneChannels`):
`/swarm/scene`, `/swarm/trails`, `/swarm/agents`, `/swarm/events` and `/swarm/run`.

What it draws is what any observer of the run receives over zenoh: the ground truth the world
publishes (at most every TRUTH_PERIOD of wall time: tick, time, and per agent its pose, turn
rate, out-neighbour and state), the events (switches, joins, drops, faults...), the world's
info (the target, each agent's role, speed and orbit radius) and the agents' statuses (each
one's follow state, `/swarm/agents`' `follow`, as its latest status said it). A scene is logged at most
SCENE_RATE times per simulated second, stamped with the run's simulated time, as the world
logs its own. An agent added at run time (`swarm spawn`) is read from the world's info when
the ground truth first has it. `/swarm/run` says what is watched: `{"run", "scenario_name",
"clock", "ticks", "dt", "target", "agents": [{"id", "role", "speed", "orbit_radius"}]}` once,
then `{"add_agent": {...}}` for each agent added.

It serves until Ctrl-C (exit 130) or until the world is gone: it ended (its end notice, or
its endpoint refusing connections: exit 0), or it stopped answering without ending
(swarm.live.client.Patience; StoppedAnswering, exit 1). Each says one line.
"""

from __future__ import annotations

import queue
import threading
import time
from typing import NamedTuple

import foxglove

from swarm.contracts import wire
from swarm.contracts.errors import NoRunError, StoppedAnswering
from swarm.contracts.vocabulary import AgentState
from swarm.live.client import LiveRun, talking
from swarm.world.live_view import open_hint, serve
from swarm.world.scene import SCENE_RATE, SceneChannels

SILENT_CHECK = 1.0  # s without ground truth before asking whether the world is still there
ACTIVE = wire.STATES.index(AgentState.ACTIVE)


class Look(NamedTuple):
    """What the scene needs of an agent (world/scene.py's SceneBuilder)."""

    id: int
    role: str
    speed: float
    orbit_radius: float | None


def looks(info: dict) -> dict[int, Look]:
    """The agents of the world's info, by id."""
    return {
        int(a["id"]): Look(int(a["id"]), str(a["role"]), float(a["speed"]), a.get("orbit_radius"))
        for a in info["agents"].values()
    }


def run_doc(info: dict) -> dict:
    """The first `/swarm/run` message of a watched run."""
    return {
        "run": info.get("run"),
        "scenario_name": info.get("scenario"),
        "clock": info.get("clock"),
        "ticks": info.get("ticks"),
        "dt": info.get("dt"),
        "target": info.get("target"),
        "agents": [a._asdict() for a in looks(info).values()],
    }


class Observer:
    """The channels of one watched run, fed from its ground truth and events (`feed`)."""

    def __init__(self, ctx, info: dict):
        self.channels = SceneChannels(ctx, tuple(info["target"]), looks(info).values(), SCENE_RATE)
        self.known = set(looks(info))
        self.channels.run(run_doc(info), float(info.get("time") or 0.0))
        self.last_scene: float | None = None  # simulated s of the last scene logged
        self.tick: int | None = None  # of the last ground truth

    def event(self, ev: dict) -> None:
        self.channels.event(ev)

    def add_agents(self, info: dict, t: float) -> None:
        """Agents of `info` not drawn yet (added at run time) are drawn from now on."""
        for aid, look in looks(info).items():
            if aid not in self.known:
                self.known.add(aid)
                self.channels.add_agent(look, look._asdict(), t)

    def truth(self, tick: int, t: float, recs, final: bool = False, follow: dict[int, str] | None = None) -> bool:
        """One ground-truth message; logs a scene (True) unless the last was under
        1/SCENE_RATE simulated s ago (and this is not the run's last tick). follow: each
        agent's follow state from its latest status (none where unknown; None or empty: the
        scene's agents have no `follow`)."""
        self.tick = tick
        if not final and self.last_scene is not None and t - self.last_scene < 1.0 / SCENE_RATE - 1e-9:
            return False
        self.last_scene = t
        codes = None
        if follow:
            codes = [wire.FOLLOW_CODE.get(follow.get(int(i), ""), 0) for i in recs["id"]]
        self.channels.tick(
            tick,
            t,
            recs["id"],
            recs["x"],
            recs["y"],
            recs["heading"],
            recs["u"],
            recs["out"],
            recs["state"] == ACTIVE,
            codes,
        )
        return True


class Feed:
    """What the run's subscriptions received, for the main thread: every event in order, the
    latest ground truth only (an observer that falls behind skips, never queues)."""

    def __init__(self):
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.latest: bytes | None = None
        self.lock = threading.Lock()
        self.follow: dict[int, str] = {}  # each agent's follow state, from its latest status

    def on_status(self, sample) -> None:
        try:
            st = wire.decode_status(sample.payload.to_bytes())
        except wire.WireError:
            return
        state = st.get("follow")
        if isinstance(state, str) and state in wire.FOLLOW_CODE:
            with self.lock:
                self.follow[st["id"]] = state

    def on_truth(self, sample) -> None:
        with self.lock:
            self.latest = sample.payload.to_bytes()
        self.q.put(None)

    def on_event(self, sample) -> None:
        self.q.put(sample.payload.to_bytes())

    def next(self, timeout: float):
        """(events, truth or None) received so far, waiting up to `timeout` s for anything."""
        events = []
        try:
            item = self.q.get(timeout=timeout)
            while True:
                if item is not None:
                    events.append(item)
                item = self.q.get_nowait()
        except queue.Empty:
            pass
        with self.lock:
            truth, self.latest = self.latest, None
        return events, truth


def serve_run(live, host: str, port: int, say) -> None:
    """Serve the live run `live` (a swarm.connect Live) on ws://host:port until its world is
    gone, saying so with `say` when the run ended. Raises swarm.world.live_view.LiveViewError (the
    port in use), StoppedAnswering (the world stopped answering without ending the run) and
    KeyboardInterrupt (Ctrl-C)."""
    info = live.info()
    ctx = foxglove.Context()
    observer = Observer(ctx, info)
    server = serve(ctx, f"swarm {live.run} (watch)", host, port)
    try:
        with talking():  # opening its own session for the subscriptions (swarm/live/client.py)
            lr = LiveRun(live.ref).__enter__()
        with lr:
            feed = Feed()
            with talking():
                subs = [
                    lr.session.declare_subscriber(wire.truth_key(live.run), feed.on_truth),
                    lr.session.declare_subscriber(wire.events_key(live.run), feed.on_event),
                    lr.session.declare_subscriber(wire.agent_key(live.run, "*", "status"), feed.on_status),
                ]
                lr.watch_end()
            say(f"run {live.run}: {open_hint(host, port)}")
            ended = _follow(live, lr, feed, observer, int(info.get("ticks") or 0))  # a bug in it: a traceback
            for s in subs:
                s.undeclare()
    finally:
        server.stop()
    last = "" if observer.tick is None else f" at tick {observer.tick}"
    if not ended:
        raise StoppedAnswering(f"the world of run {live.run} stopped answering{last}; the live view is closed")
    say(f"run {live.run} ended{last}; the live view is closed")


def _follow(live, lr, feed: Feed, observer: Observer, ticks: int) -> bool:
    """Feed `observer` until the world is gone: True when it ended (its end notice, or its
    endpoint refusing connections), False when it stopped answering."""
    heard = time.monotonic()
    info = None
    while True:
        events, truth = feed.next(0.25)
        for buf in events:
            try:
                observer.event(wire.decode_event(buf))
            except wire.WireError:
                pass  # not from the world (the hub lets only the world put events)
        if truth is not None:
            heard = time.monotonic()
            try:
                tick, t, recs = wire.decode_truth(truth)
            except wire.WireError:
                continue
            if not observer.known.issuperset(int(i) for i in recs["id"]):
                try:
                    info = live.again(live.info, None)  # an agent added at run time: its role and speed
                except StoppedAnswering:
                    return False
                except NoRunError:  # gone: its end notice, or its endpoint refusing connections
                    return True
                if info is not None:
                    observer.add_agents(info, t)
            if observer.known.issuperset(int(i) for i in recs["id"]):
                with feed.lock:
                    follow = dict(feed.follow)
                observer.truth(tick, t, recs, final=tick >= ticks, follow=follow)
        if lr.end_notice:
            time.sleep(0.2)  # what the world sent before its notice
            if feed.latest is not None or not feed.q.empty():
                continue
            return True
        if time.monotonic() - heard > SILENT_CHECK:  # paused, stalled or gone
            heard = time.monotonic()
            try:
                info = live.again(live.info, info)
            except StoppedAnswering:
                return False
            except NoRunError:
                return True
