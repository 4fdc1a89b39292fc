"""`swarm study`'s option text made into values (a clear message naming the option, exit 2),
and its printed tables (swarm/cli/study.py)."""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Optional

import typer

from swarm.contracts.vocabulary import ExitCode


def fail(message: str, code: int = ExitCode.USAGE) -> typer.Exit:
    typer.secho(message, err=True, fg=typer.colors.RED)
    return typer.Exit(code)


def floats(option: str, text: str, *, positive: bool = True, allow_inf: bool = False) -> list[float]:
    """'1,2.5' -> [1.0, 2.5]; 'inf' where allowed; a clear message naming the option."""
    out = []
    for part in text.split(","):
        part = part.strip()
        try:
            v = float(part)
        except ValueError:
            raise fail(f"{option}: {part!r} is not a number (give a comma-separated list, e.g. 1,2.5)") from None
        if math.isnan(v) or (math.isinf(v) and not allow_inf) or (positive and v <= 0):
            raise fail(
                f"{option}: {part!r} must be a {'positive ' if positive else ''}finite number"
                + (" or inf" if allow_inf else "")
            )
        out.append(v)
    return out


def ints(option: str, text: str, minimum: int) -> list[int]:
    out = []
    for part in text.split(","):
        try:
            v = int(part.strip())
        except ValueError:
            raise fail(f"{option}: {part.strip()!r} is not a whole number") from None
        if v < minimum:
            raise fail(f"{option}: {v} must be at least {minimum}")
        out.append(v)
    return out


def sweep(option: str, text: Optional[str], *, lo: float, hi: float, inf: bool = False) -> list[float]:
    """A swept list option: numbers in [lo, hi] (inf too where allowed)."""
    if text is None:
        return []
    out = []
    for v in floats(option, text, positive=False, allow_inf=inf):
        if not (lo <= v <= hi or (inf and math.isinf(v) and v > 0)):
            raise fail(f"{option}: {v:g} is out of range [{lo:g}, {hi:g}]" + (" (or inf)" if inf else ""))
        out.append(v)
    return out


def params(texts: list[str]) -> tuple[dict[str, list[float]], dict[str, str]]:
    """--param NAME=V1,V2 (a law parameter: "param.NAME") or tuning.FIELD=V1,V2 (a field of
    [sensing.tuning]: "tuning.FIELD"); (the grid's entries, each key's option for messages)."""
    grid, labels = {}, {}
    for t in texts:
        name, eq, values = t.partition("=")
        name = name.strip()
        kind, dot, field = name.partition(".")
        tuning = dot and kind == "tuning" and field.isidentifier()
        if not eq or not (name.isidentifier() or tuning):
            raise fail(f"--param: {t!r}: give NAME=V1,V2,... (e.g. k=0.1,0.2, or tuning.coast_s=2,5,8)")
        key = name if tuning else f"param.{name}"
        grid[key] = floats(f"--param {name}", values, positive=False)
        labels[key] = f"--param {name}"
    return grid, labels


def num(fmt: str) -> Callable:
    return lambda v: "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def table(rows: list[dict], columns: list[tuple[str, str, Callable]]) -> None:
    """Rows under their headers; "-" where a row has no value (a setting whose runs all timed out)."""

    def text(r: dict, k: str, fmt: Callable) -> str:
        return "-" if r.get(k) is None else fmt(r[k])

    widths = [max(len(h), *(len(text(r, k, fmt)) for r in rows)) if rows else len(h) for h, k, fmt in columns]
    typer.echo("  ".join(h.rjust(w) for (h, _, _), w in zip(columns, widths)))
    for r in rows:
        typer.echo("  ".join(text(r, k, fmt).rjust(w) for (_, k, fmt), w in zip(columns, widths)))


def safety_table(summary: list[dict]) -> None:
    """The safety figures per setting, when the runs measured them (a [safety] table)."""
    if not any("collisions" in r for r in summary):
        return
    table(
        summary,
        [
            ("setting", "setting", str),
            ("safe runs", "safe_runs", str),
            ("collisions", "collisions", str),
            ("exits", "boundary_exits", str),
            ("saturations", "saturations", str),
            ("min dist m", "min_distance", num(".3g")),
            ("interventions", "interventions", str),
            ("no safe cmd", "infeasible", str),
        ],
    )


def state_table(summary: list[dict]) -> None:
    """The time per selection state per setting (s per follower, mean over runs), when the
    runs counted it (summary.json's state_s); states nobody was in left out."""
    keys = [k for k in dict.fromkeys(k for r in summary for k in r) if k.startswith("state_s_")]
    keys = [k for k in keys if any(r.get(k, 0) for r in summary)]
    if not keys:
        return
    typer.echo("s per follower in each selection state (mean over runs):")
    table(summary, [("setting", "setting", str)] + [(k.removeprefix("state_s_"), k, num(".1f")) for k in keys])


def gain_table(summary: list[dict]) -> None:
    """Rows (C1, C2), columns speed ratio: worst settling time (s), '-' for never."""
    ratios = sorted({r["ratio"] for r in summary})
    cells = {(r["c1"], r["c2"], r["ratio"]): r["worst_settling_s"] for r in summary}
    pairs = sorted({(r["c1"], r["c2"]) for r in summary})
    typer.echo("worst time into the 2% band (s; '-': never), rows C1, C2; columns follower/leader speed ratio")
    typer.echo(f"{'C1':>5} {'C2':>5} " + " ".join(f"{q:>6g}" for q in ratios))
    for a, b in pairs:
        vals = [cells.get((a, b, q), math.nan) for q in ratios]
        typer.echo(f"{a:>5g} {b:>5g} " + " ".join(f"{v:>6.0f}" if math.isfinite(v) else f"{'-':>6}" for v in vals))
