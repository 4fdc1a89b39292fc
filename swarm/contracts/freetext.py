"""Free text that comes over the bus, made safe for the record and for a terminal, and the
budget that keeps one identity's requests from growing the record without bound.

Text that others write (who asked for a pause or a stop, an agent's host name, its status,
the last lines of an agent's log in a crash report) reaches the run's record (summary.json),
the world's log and the terminals of `swarm up`, `swarm echo` and `swarm logs`. `printable`
is the one sanitiser: every control character (C0, DEL, C1, line and paragraph separators,
format characters such as bidirectional overrides, lone surrogates) is written as Python's
repr writes it (`\\x1b`, `\\n`, `\\u202e`), so no text can move a terminal's cursor, set
its title, clear it or start a line of its own; and the text is cut to a limit (its
escaped length), with how long it was. The world applies it where it accepts the text
(swarm/contracts/wire.py's decoders of requests, world/inbox.py), and the programs that
print such text apply it again before printing (defence in depth: a record written by an
older world, a log written by any process).

`Budget` is a token bucket (pure: the caller passes the time): `take(now)` says whether one
more event may be written now. world/inbox.py gives the operator's pause/resume events one.
"""

from __future__ import annotations

import unicodedata

__all__ = ["BY_CHARS", "HOST_CHARS", "TEXT_CHARS", "Budget", "printable"]

BY_CHARS = 200  # who asked (pause, resume, stop): at most this many characters, escaped
HOST_CHARS = 255  # a host name an agent gives (longer than any real one, RFC 1035: 253)
TEXT_CHARS = 500  # any other free-text field from the bus (a status's strings, a log line)

# control, format, surrogate, private use, unassigned, line and paragraph separators
_UNSAFE = frozenset(("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"))


def _escape(ch: str) -> str:
    """One character as repr writes it inside a string: \\n, \\x1b, \\u202e, \\U000e0001."""
    if ch in "\n\r\t":
        return {"\n": "\\n", "\r": "\\r", "\t": "\\t"}[ch]
    n = ord(ch)
    if n < 0x100:
        return f"\\x{n:02x}"
    if n < 0x10000:
        return f"\\u{n:04x}"
    return f"\\U{n:08x}"


def printable(text: object, limit: int | None = TEXT_CHARS, keep: str = "") -> str:
    """`text` (str() of it, if not a str) with every unsafe character escaped (the module
    says which; those in `keep` excepted, e.g. "\\t" for a log line), cut so that the result
    has at most `limit` characters plus a short tail that says how long it was
    (`... (61440 characters)`); `limit` None: not cut. Text without unsafe characters and
    within the limit is returned as it is."""
    s = text if isinstance(text, str) else str(text)
    if (limit is None or len(s) <= limit) and s.isprintable():
        return s  # the common case, in C (isprintable is False for every unsafe category, and more)
    out: list[str] = []
    size = 0
    for ch in s:
        piece = ch
        if ch not in keep and (unicodedata.category(ch) in _UNSAFE or ch in "\n\r\t"):
            piece = _escape(ch)
        if limit is not None and size + len(piece) > limit:
            out.append(f"... ({len(s)} characters)")
            break
        out.append(piece)
        size += len(piece)
    return "".join(out)


class Budget:
    """A token bucket: at most `burst` events at once, refilled at `rate` a second. `take(now)`
    (now: monotonic seconds) spends one token if there is one and says whether it did;
    `ready(now)` whether one is there, without spending it."""

    def __init__(self, rate: float, burst: int):
        if rate <= 0 or burst < 1:
            raise ValueError("a budget needs rate > 0 and burst >= 1")
        self.rate = float(rate)
        self.burst = float(burst)
        self.tokens = float(burst)
        self.at: float | None = None

    def _refill(self, now: float) -> None:
        if self.at is not None and now > self.at:
            self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate)
        if self.at is None or now > self.at:
            self.at = now

    def ready(self, now: float) -> bool:
        self._refill(now)
        return self.tokens >= 1.0

    def take(self, now: float) -> bool:
        if not self.ready(now):
            return False
        self.tokens -= 1.0
        return True
