"""`Record`: a JSON object with attribute access, what the API returns for summaries and live
readings (swarm/api/runs.py, swarm/api/live.py), and `Summary`, summary.json as one (exported
by swarm/api/runs.py). Their own module so that the live path imports neither numpy nor the
scenario model, and the `swarm up` launcher (swarm/api/launch.py) no numpy."""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from typing import Any

__all__ = ["Record", "Summary"]


def _wrap(v: Any) -> Any:
    if isinstance(v, Mapping) and not isinstance(v, Record):
        return Record(v)
    if isinstance(v, list):
        return [_wrap(x) for x in v]
    return v


class Record(Mapping):
    """A JSON object with attribute access: `r.converged` is `r["converged"]`; nested
    objects are Records too. `to_dict()` gives the plain data back."""

    def __init__(self, data: Mapping):
        object.__setattr__(self, "_data", dict(data))

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return _wrap(self._data[name])
        except KeyError:
            raise AttributeError(f"no field {name!r} here (fields: {', '.join(map(str, self._data))})") from None

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("read-only")

    def __getitem__(self, key: Any) -> Any:
        return _wrap(self._data[key])

    def __iter__(self) -> Iterator:
        return iter(self._data)

    def __len__(self) -> int:
        return len(self._data)

    def __dir__(self) -> list[str]:
        return sorted(k for k in self._data if isinstance(k, str) and k.isidentifier())

    def __repr__(self) -> str:
        shown = ", ".join(f"{k}={v!r}" for k, v in self._data.items() if not isinstance(v, (dict, list)))
        return f"{type(self).__name__}({shown[:300]}{'...' if len(shown) > 300 else ''})"

    def to_dict(self) -> dict:
        return self._data


class Summary(Record):
    """summary.json (docs/reference/outputs.md#summary) with attribute access; `agents` is keyed
    by int id, `events` is a list of Records (`ev["from"]` for a switch's `from`)."""

    @property
    def agents(self) -> dict[int, Record]:
        return {int(k): Record(v) for k, v in self._data.get("agents", {}).items()}

    def per_agent(self, field: str) -> dict[int, Any]:
        """One field of every agent, by id: `summary.per_agent("radial_error")`."""
        return {aid: a.get(field) for aid, a in self.agents.items()}

    def events_of(self, kind: str) -> list[Record]:
        return [e for e in self.events if e.get("kind") == kind]
