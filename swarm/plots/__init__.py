"""Figures of one run, laid out like the paper's Fig. 4/5, in PNG, PDF or SVG.

`render_plots(run_dir, formats=("png",))` reads ``trajectory.npz`` and ``summary.json``
from a run directory (world/run_reader.py) and writes, next to them:

- ``graph.png``        (a) the final communication graph
- ``trajectories.png`` (b) x-y paths with start/final markers, target and expected orbits
- ``distance.png``     (c) distance from the target vs time, dashed expected radii
- ``control.png``      (d) turn-rate inputs u vs time (y-range from the followers; the
                       leaders' start clipped and marked)
- ``overview.png``     the four panels in one 2x2 figure (paper layout)
- ``neighbours.png``   each follower's out-neighbour over time (the dynamic graph)
- ``states.png``       each follower's follow state over time (keep, hold, coast, shadow,
                       search, ...); not for a run recorded without them

(``.pdf`` / ``.svg`` for the other formats). `render_animation` writes ``animation.gif``.
Every agent has one colour and label in all of them (leaders "L<id>", thicker, starred);
above `GROUP_ABOVE` agents (c) and (d) become small multiples, a panel per tree.

Modules: `style` (fixed colours, sizes, decimation), `palette` (each agent's colour,
label, width and tree), `context` (what a run's figures share), `placement` (labels and
markers kept apart), `clipping` (the control panel's y-range), `trajectories`,
`timeseries` (distance, control), `groups` (small multiples), `graph` (final and dynamic
graph), `states` (the follow states), `render` (the figures, formats, saving), `animate` (the GIF). Long runs are
decimated to at most `MAX_POINTS` points per line. Only the headless Agg backend is used.

Any problem with the input files comes out as a `PlotError` whose message names
the file.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

from swarm.plots.animate import ANIMATION_FILE, render_animation  # noqa: E402
from swarm.plots.render import FORMATS, PLOT_FILES, check_formats, render_plots  # noqa: E402
from swarm.plots.style import MAX_POINTS  # noqa: E402
from swarm.world.run_reader import RunData, final_graph, load_run, switch_count  # noqa: E402
from swarm.world.run_reader import RunReadError as PlotError  # noqa: E402

__all__ = [
    "PlotError",
    "RunData",
    "load_run",
    "render_plots",
    "render_animation",
    "final_graph",
    "switch_count",
    "MAX_POINTS",
    "PLOT_FILES",
    "FORMATS",
    "ANIMATION_FILE",
    "check_formats",
]
