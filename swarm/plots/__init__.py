"""PNG plots of one run, laid out like the paper's Fig. 4/5.

`render_plots(run_dir)` reads ``trajectory.npz`` and ``summary.json`` from a run
directory (world/run_reader.py) and writes, next to them:

- ``graph.png``        (a) the final communication graph
- ``trajectories.png`` (b) x-y paths with start/final markers, target and expected orbits
- ``distance.png``     (c) distance from the target vs time, dashed expected radii
- ``control.png``      (d) turn-rate inputs u vs time
- ``overview.png``     the four panels in one 2x2 figure (paper layout)
- ``neighbours.png``   each follower's out-neighbour over time (the dynamic graph)

Out-neighbour switches are marked on the distance plot (small ticks on the lines) and
counted in the final-graph panel's title.

Modules: `style` (colours, sizes, legends, decimation), `trajectories`, `timeseries`
(distance, control), `graph` (final and dynamic graph), `render` (the figures, saving).
Every agent is labelled by its id. Long runs are decimated to at most `MAX_POINTS`
points per line. Only the headless Agg backend is used.

Any problem with the input files comes out as a `PlotError` whose message names
the file.
"""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")

from swarm.plots.render import PLOT_FILES, render_plots  # noqa: E402
from swarm.plots.style import MAX_POINTS  # noqa: E402
from world.run_reader import RunData, final_graph, load_run, switch_count  # noqa: E402
from world.run_reader import RunReadError as PlotError  # noqa: E402

__all__ = ["PlotError", "RunData", "load_run", "render_plots", "final_graph", "switch_count", "MAX_POINTS", "PLOT_FILES"]
