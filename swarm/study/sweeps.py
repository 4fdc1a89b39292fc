"""What `swarm.study.run_scenario` may sweep (its `grid`), checked before anything runs.

A grid's keys: the axes of swarm/study/scenario.py (`c1`, `c2`, `range`, `fov`, `noise`,
`loss`, `delay`, `safety`, `gamma`), `param.NAME` (an entry of the scenario's [law.params]) and
`tuning.NAME` (a field of the scenario's [sensing.tuning], the sticky rule's selection tuning:
swarm/contracts/tuning.py `SelectionTuning`). Each maps to the list of values to run; the
settings are every combination, in `ORDER` (so the CSV's columns do not depend on the order
the grid was written in).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

from swarm.contracts.errors import UsageError
from swarm.contracts.tuning import SelectionTuning

# axis -> (lowest, highest, inf allowed) (c1 and c2: positive and finite)
BOUNDS: dict[str, tuple[float, float, bool]] = {
    "range": (1e-9, math.inf, True),
    "fov": (1e-3, 2 * math.pi, False),
    "noise": (0.0, math.pi, False),
    "loss": (0.0, 1.0, False),
    "delay": (0.0, math.inf, False),
    "safety": (0.0, 1.0, False),
    "gamma": (1e-9, 1e6, False),
}
ORDER = ("c1", "c2", "param.", "tuning.", "range", "fov", "noise", "loss", "delay", "safety", "gamma")


def tuning_fields() -> tuple[str, ...]:
    """The fields of [sensing.tuning] (swarm/contracts/tuning.py)."""
    return tuple(SelectionTuning.model_fields)


def check_tuning(name: str, label: str) -> None:
    """UsageError unless `name` is a field of [sensing.tuning]; `label` names the option."""
    valid = tuning_fields()
    if name not in valid:
        raise UsageError(
            f"{label}: {name!r} is not a field of the selection tuning [sensing.tuning]; the fields: {', '.join(valid)}"
        )


def check_values(axis: str, values: Sequence[float], label: str) -> list[float]:
    """The values of one axis as floats; UsageError naming `label` for one out of range."""
    out = []
    for v in values:
        try:
            v = float(v)
        except (TypeError, ValueError):
            raise UsageError(f"{label}: {v!r} is not a number") from None
        if math.isnan(v):
            raise UsageError(f"{label}: nan is not a value")
        if axis in ("c1", "c2") and not (0 < v < math.inf):
            raise UsageError(f"{label}: {v:g} must be a positive finite number")
        if axis in BOUNDS:
            lo, hi, inf = BOUNDS[axis]
            if not (lo <= v <= hi or (inf and math.isinf(v) and v > 0)):
                raise UsageError(f"{label}: {v:g} is out of range [{lo:g}, {hi:g}]" + (" (or inf)" if inf else ""))
        elif axis.startswith(("param.", "tuning.")) and math.isinf(v):
            raise UsageError(f"{label}: {v:g} must be finite")
        out.append(v)
    if axis == "safety" and any(v not in (0.0, 1.0) for v in out):
        raise UsageError(f"{label}: 0 (off, measuring only) or 1 (on)")
    return out


def grid_axes(
    grid: Mapping[str, Sequence[float] | float], labels: Mapping[str, str] | None = None
) -> dict[str, list[float]]:
    """The grid checked and in ORDER (keys with an empty list left out); `labels` names each
    key's option in messages (the command line's), else the key itself."""
    labels = labels or {}
    out: dict[str, list[float]] = {}
    for key, values in grid.items():
        label = labels.get(key, f"grid[{key!r}]")
        values = [values] if isinstance(values, (int, float)) else list(values)
        kind, dot, name = key.partition(".")
        if dot and kind == "param":
            if not name.isidentifier():
                raise UsageError(f"{label}: {name!r} is not a parameter name")
        elif dot and kind == "tuning":
            check_tuning(name, label)
        elif key not in ORDER:
            axes = ", ".join(k for k in ORDER if "." not in k)
            raise UsageError(
                f"{label}: {key!r} is not an axis of a scenario study: one of {axes}, "
                "param.NAME (a law parameter) or tuning.NAME (a selection tuning field)"
            )
        vals = check_values(key, list(values), label)
        if vals:
            out[key] = vals

    def rank(k: str) -> int:
        return ORDER.index(k.partition(".")[0] + "." if "." in k else k)

    return {k: out[k] for k in sorted(out, key=rank)}  # sorted is stable: params keep their order
