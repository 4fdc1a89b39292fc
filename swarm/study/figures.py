"""Figures of `swarm study` (headless Agg): study.png for random swarms, gains.png for
the (C1, C2) x speed-ratio map of the single pair."""

from __future__ import annotations

import math
import textwrap
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402

from swarm.study.swarms import SwarmSetting, is_true, setting_of  # noqa: E402


def plot_swarms(summary: list[dict], rows: list[dict], path: Path) -> Path:
    """Three panels per setting: converged fraction of all runs (how many were cut off at t = 0 noted),
    settling times of the converged runs, and switches per follower."""
    labels = [s["setting"] for s in summary]
    by_label: dict[str, list[dict]] = {}
    for r in rows:
        by_label.setdefault(SwarmSetting(*setting_of(r)).label(), []).append(r)
    fig, axs = plt.subplots(1, 3, figsize=(15, 1.6 + 0.45 * len(labels) + 2), layout="constrained")
    y = np.arange(len(labels))
    ax = axs[0]
    frac = [s["converged_fraction"] if math.isfinite(s["converged_fraction"]) else 0.0 for s in summary]
    ax.barh(y, frac, color=["tab:green" if f >= 0.99 else "tab:orange" if f >= 0.5 else "tab:red" for f in frac])
    for k, s in enumerate(summary):
        note = f" {s['converged']}/{s['runs']}" + (f" ({s['cut_off']} cut off at t = 0)" if s["cut_off"] else "")
        ax.text(min(frac[k], 0.55), k, note, va="center", fontsize=8)
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlim(0, 1)
    ax.axvline(0.99, color="0.4", ls=":", lw=0.8)
    ax.invert_yaxis()
    ax.set_xlabel("converged fraction")
    ax.set_title("converged within the run")
    ax = axs[1]
    data = [
        [
            float(r["settling_time"])
            for r in by_label.get(lab, [])
            if is_true(r["converged"]) and math.isfinite(float(r["settling_time"]))
        ]
        or [math.nan]
        for lab in labels
    ]
    ax.boxplot(data, orientation="horizontal", positions=y, widths=0.6, showfliers=True)
    ax.set_yticks(y, [""] * len(labels))
    ax.invert_yaxis()
    ax.set_xlabel("settling time of converged runs (s)")
    ax.set_title("last agent into the 2% band")
    ax = axs[2]
    sw = [
        [int(c) for r in by_label.get(lab, []) for c in str(r["switch_counts"]).split(";") if c != ""] or [0]
        for lab in labels
    ]
    ax.boxplot([np.asarray(v) + 1 for v in sw], orientation="horizontal", positions=y, widths=0.6)
    ax.set_xscale("log")
    ax.set_yticks(y, [""] * len(labels))
    ax.invert_yaxis()
    ax.set_xlabel("switches per follower + 1 (log)")
    ax.set_title("out-neighbour switches")
    for a in axs:
        a.grid(True, axis="x", lw=0.3, alpha=0.5)
    fig.suptitle(f"swarm study: {sum(s['runs'] for s in summary)} random swarms")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_gains(summary: list[dict], path: Path, duration: float) -> Path:
    """gains_figure, written to `path`."""
    fig = gains_figure(summary, duration)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def gains_figure(summary: list[dict], duration: float) -> Figure:
    """One panel per C1: C2 against speed ratio, coloured by the worst settling time;
    grey ("never") where some start had not settled by the end of its run (`duration` s)."""
    c1s = sorted({r["c1"] for r in summary})
    c2s = sorted({r["c2"] for r in summary})
    ratios = sorted({r["ratio"] for r in summary})
    cells = {(r["c1"], r["c2"], r["ratio"]): r["worst_settling_s"] for r in summary}
    finite = [v for v in cells.values() if math.isfinite(v)]
    vmax = max(finite) if finite else 1.0
    # at least 8 x 3.4 in, and the title wrapped to the width: a small grid keeps its
    # title and colour-bar label whole
    width = max(8.0, 1.2 + 0.55 * len(ratios) * len(c1s) + 1.5)
    height = max(3.4, 1.9 + 0.5 * len(c2s))
    fig, axs = plt.subplots(1, len(c1s), figsize=(width, height), layout="constrained", squeeze=False)
    im = None
    for ax, a in zip(axs[0], c1s):
        grid = np.array([[cells.get((a, b, q), math.nan) for q in ratios] for b in c2s])
        never = ~np.isfinite(grid)
        ax.imshow(np.where(never, 1.0, np.nan), cmap="Greys", vmin=0, vmax=4, origin="lower", aspect="auto")
        im = ax.imshow(
            np.where(never, np.nan, grid), cmap="viridis_r", vmin=0, vmax=vmax, origin="lower", aspect="auto"
        )
        for i in range(len(c2s)):
            for j in range(len(ratios)):
                ax.text(
                    j,
                    i,
                    "never" if never[i, j] else f"{grid[i, j]:.0f}",
                    ha="center",
                    va="center",
                    fontsize=6,
                    color="w" if not never[i, j] and grid[i, j] > 0.5 * vmax else "k",
                )
        ax.set_xticks(range(len(ratios)), [f"{q:g}" for q in ratios], fontsize=7)
        ax.set_yticks(range(len(c2s)), [f"{b:g}" for b in c2s], fontsize=7)
        ax.set_xlabel("speed ratio v_i / v_j")
        ax.set_ylabel("C2 / omega")
        ax.set_title(f"C1 / omega = {a:g}")
    if im is not None:
        fig.colorbar(im, ax=axs[0].tolist(), label="worst time into\nthe 2% band (1/omega)")
    title = (
        f"single follower behind a leader on its orbit (omega = 1 rad/s): where the law settles "
        f"within {duration:g} s (worst of the starts)"
    )
    fig.suptitle(textwrap.fill(title, int(width * 9)))
    return fig


def plot_scenario_study(summary: list[dict], rows: list[dict], path: Path, title: str) -> Path:
    """`swarm study scenario`: per setting, the converged share of its runs and the
    settling times of its converged runs."""
    labels = [s["setting"] for s in summary]
    by_label: dict[str, list[dict]] = {}
    for r in rows:
        by_label.setdefault(str(r["setting"]), []).append(r)
    fig, axs = plt.subplots(1, 2, figsize=(11, 2.2 + 0.4 * len(labels)), layout="constrained")
    y = np.arange(len(labels))
    ax = axs[0]
    frac = [float(s["converged_fraction"]) for s in summary]
    ax.barh(y, frac, color=["tab:green" if f >= 0.99 else "tab:orange" if f >= 0.5 else "tab:red" for f in frac])
    for k, s in enumerate(summary):
        ax.text(min(frac[k], 0.75) + 0.01, k, f"{s['converged']}/{s['runs']}", va="center", fontsize=8)
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlim(0, 1)
    ax.invert_yaxis()
    ax.set_xlabel("converged share")
    ax.set_title("converged within the run")
    ax = axs[1]
    data = [_settling(by_label.get(lab, [])) or [math.nan] for lab in labels]
    ax.boxplot(data, orientation="horizontal", positions=y, widths=0.6)
    ax.set_yticks(y, [""] * len(labels))
    ax.invert_yaxis()
    ax.set_xlabel("settling time of converged runs (s)")
    ax.set_title("last agent into the 2% band")
    for a in axs:
        a.grid(True, axis="x", lw=0.3, alpha=0.5)
    fig.suptitle(textwrap.fill(title, 110))
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _settling(rows: list[dict]) -> list[float]:
    return [
        float(r["settling_time"]) for r in rows if is_true(r["converged"]) and math.isfinite(float(r["settling_time"]))
    ]


SWEEP_UNITS = {
    "c1": "C1 (1/s)",
    "c2": "C2 (rad/s)",
    "range": "sensing range (m)",
    "fov": "field of view (rad)",
    "noise": "sensing noise std (rad)",
    "loss": "loss probability",
    "delay": "sensor-frame delay (s)",
}


def plot_sweep(rows: list[dict], axes: list[str], path: Path, title: str) -> Path:
    """sweep_figure, written to `path`."""
    fig = sweep_figure(rows, axes, title)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def sweep_figure(rows: list[dict], axes: list[str], title: str) -> Figure:
    """One column per swept parameter (axes with more than one value): the converged share
    and the settling time of converged runs (median, 10-90% band) against its values, over
    every run at that value (the other parameters' values pooled). Both panels of a column
    share its x axis, which spans the swept values even where no run converged (the lower
    panel then has no data to scale to: it says so and shows no time scale)."""
    width = max(6.0, 3.6 * len(axes))
    fig, axs = plt.subplots(2, len(axes), figsize=(width, 5.2), layout="constrained", squeeze=False, sharex="col")
    for k, name in enumerate(axes):
        values = sorted({float(r[name]) for r in rows})
        at = {v: [r for r in rows if float(r[name]) == v] for v in values}
        categorical = any(math.isinf(v) for v in values)
        xs = np.arange(len(values), dtype=float) if categorical else np.asarray(values)
        share = [sum(is_true(r["converged"]) for r in at[v]) / len(at[v]) for v in values]
        ax = axs[0, k]
        ax.plot(xs, share, "o-", color="tab:green")
        ax.set_ylim(-0.03, 1.03)
        ax.set_ylabel("converged share" if k == 0 else "")
        ax.set_title(name.removeprefix("param.") + (" ([law.params])" if name.startswith("param.") else ""))
        ax = axs[1, k]
        st = [_settling(at[v]) for v in values]
        med = [float(np.median(s)) if s else math.nan for s in st]
        lo = [float(np.percentile(s, 10)) if s else math.nan for s in st]
        hi = [float(np.percentile(s, 90)) if s else math.nan for s in st]
        ax.fill_between(xs, lo, hi, color="tab:blue", alpha=0.2, lw=0, label="10-90%")
        ax.plot(xs, med, "o-", color="tab:blue", label="median")
        ax.set_ylabel("settling time of\nconverged runs (s)" if k == 0 else "")
        ax.set_xlabel(SWEEP_UNITS.get(name, name.removeprefix("param.")))
        if not any(st):  # nothing to scale the panel to: matplotlib would show -0.05..0.05 on both axes
            ax.text(0.5, 0.5, "no converged run", transform=ax.transAxes, ha="center", va="center", color="0.4")
            ax.set_ylim(0.0, 1.0)
            ax.tick_params(axis="y", labelleft=False, left=False)
        elif k == 0:
            ax.legend(fontsize=7)
        # the swept values, whatever the data: a margin of 5% of their span (or of the value, for one)
        span = float(xs[-1] - xs[0]) or abs(float(xs[0])) or 1.0
        ax.set_xlim(float(xs[0]) - 0.05 * span, float(xs[-1]) + 0.05 * span)
        for a in axs[:, k]:
            a.grid(True, lw=0.3, alpha=0.5)
        if categorical:
            ax.set_xticks(xs, [f"{v:g}" for v in values])
    fig.suptitle(textwrap.fill(title, int(width * 9)))
    return fig
