"""The live view: with `--foxglove`, the world serves its run over Foxglove's WebSocket
protocol (foxglove-sdk's server), so the Foxglove app can watch it as it goes.

The server is attached to the context of the run's recording writer (world/stream.py), so
it serves exactly the recording's channels, as they are logged, with nothing logged twice:
`/swarm/scene`, `/swarm/trails`, `/swarm/agents`, `/swarm/events` and `/swarm/run`. Only
`/swarm/ticks` (every tick, in the project's own binary encoding, which Foxglove cannot
draw) is left out. Without --foxglove nothing here runs (and foxglove is not imported).

`swarm watch --foxglove` serves the same channels from an observer of a live run
(swarm/live/foxglove.py), with `serve` on a context of its own.
"""

from __future__ import annotations

import re
from typing import Any

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8765
LIVE_TOPICS = ("/swarm/scene", "/swarm/trails", "/swarm/agents", "/swarm/events", "/swarm/run")


class LiveViewError(Exception):
    """The live view cannot be served (the port is in use, the host unusable)."""


def _serve(channel: Any) -> bool:
    return channel.topic != "/swarm/ticks"


def serve(ctx: Any, name: str, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT) -> Any:
    """Serve the channels of `ctx` (a foxglove.Context; all but `/swarm/ticks`) on
    ws://host:port as server `name`; returns the server (`.stop()` ends it). Raises
    LiveViewError with one line naming host and port on failure (the port in use)."""
    import foxglove  # lazy: `swarm watch` imports this module and must start fast without --foxglove

    try:
        return foxglove.start_server(name=name, host=host, port=port, context=ctx, channel_filter=_serve)
    except Exception as e:  # foxglove reports a bind failure as RuntimeError
        why = re.sub(
            r" \(os error \d+\)$", "", str(e).removeprefix("FoxgloveError: ").removeprefix("Failed to bind port: ")
        )  # as `swarm up`'s own check says it
        raise LiveViewError(f"--foxglove: cannot serve on {host}:{port}: {why}") from None


def start_live_view(writer: Any, run: str, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT) -> Any:
    """Serve `writer`'s channels (a world/stream.py StreamWriter) on ws://host:port."""
    return serve(writer.ctx, f"swarm {run}", host, port)


def live_url(host: str, port: int) -> str:
    return f"ws://{host}:{port}"


def open_hint(host: str, port: int) -> str:
    """The line to print: where to point the Foxglove app."""
    return (
        f"live view: {live_url(host, port)}  (Foxglove: Open connection > Foxglove WebSocket; "
        "a layout for the run's agents: `swarm plot` of its results writes foxglove-layout.json)"
    )
