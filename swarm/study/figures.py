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
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
