"""The paper's case 2 (two leaders, four followers) through the Python API, as notebook
cells: `# %%` starts a cell (VS Code, PyCharm and Jupytext run them one by one), or run
the whole file:

    .venv/bin/python examples/case2_notebook.py [FIGURE.png]

It writes one figure (paths, and each agent's distance to the target against its expected
radius) to FIGURE.png, by default into a new temporary directory, and prints its path.
"""

# %% Imports. `import swarm` is the API; matplotlib draws our own figure.
import sys
import tempfile
from pathlib import Path

import matplotlib

if "ipykernel" not in sys.modules:
    matplotlib.use("Agg")  # a script draws into a file; a notebook keeps its own backend
import matplotlib.pyplot as plt
import numpy as np

import swarm

# %% Load the scenario: the same file, and the same checks, as `swarm sim` / `swarm up`.
repo = Path(__file__).resolve().parents[1] if "__file__" in globals() else Path.cwd()
scenario = swarm.load(repo / "scenarios" / "case2.toml")
print(scenario.name, "-", len(scenario.agents), "agents,", scenario.run.duration, "s")

# Scenarios can also be made in code: swarm.from_dict({...}) or swarm.Builder(...), e.g.
#   b = swarm.Builder("pair", dt=0.05, duration=60, c1=1.0, c2=0.5)
#   b.leader(1, x=2, y=0, heading=1.57, speed=1.0, orbit_radius=1.0).follower(2, x=0, y=-3, heading=0, speed=1.5)
#   scenario = b.build()

# %% Run it in this process: `swarm sim`'s engine, the results in memory.
results = swarm.simulate(scenario)  # out="runs/case2-api" would also write the run directory
print(results)

# %% The summary: summary.json with attribute access.
summary = results.summary
print("converged:", summary.converged, " switches:", summary.switches, " sim time:", summary.sim_time, "s")
for aid, a in summary.agents.items():
    error = "-" if a.relative_error is None else f"{100 * a.relative_error:.3f} %"
    print(
        f"  agent {aid} {a.role:<8} out-neighbour {a.out_neighbour}  radius {a.final_radius:7.2f} m "
        f"(expected {a.expected_radius:.2f})  error {error}"
    )

# %% Our own figure from the arrays: (T, N) arrays by column, or one agent's by id.
tx, ty = results.target
fig, (paths, dist) = plt.subplots(1, 2, figsize=(12, 5), layout="constrained")
for aid, track in results.agents.items():
    (line,) = paths.plot(
        track.x,
        track.y,
        lw=2.0 if track.role == "leader" else 1.0,
        label=f"{'L' if track.role == 'leader' else ''}{aid}",
    )
    paths.plot(track.x[0], track.y[0], "o", color=line.get_color())
    dist.plot(track.t, np.hypot(track.x - tx, track.y - ty), color=line.get_color(), label=line.get_label())
    expected = summary.agents[aid].expected_radius
    if expected is not None:
        dist.axhline(expected, color=line.get_color(), ls="--", lw=0.8)
paths.plot(tx, ty, "k*", ms=12)
paths.set(aspect="equal", xlabel="x (m)", ylabel="y (m)", title="case 2: paths")
dist.set(xlabel="t (s)", ylabel="distance to the target (m)", title="distance (dashed: expected radius)")
paths.legend(loc="upper right", fontsize=8)

# %% Save it: to the path given on the command line, else into a new temporary directory.
given = [a for a in sys.argv[1:] if a.endswith(".png")]
figure = Path(given[0]) if given else Path(tempfile.mkdtemp(prefix="case2-")) / "case2.png"
figure.parent.mkdir(parents=True, exist_ok=True)
fig.savefig(figure, dpi=100)
print("figure:", figure)

# %% More: the paper-style figures `swarm plot` draws, from these results:
#   results.plot(out_dir="runs/case2-api")            # overview.png, trajectories.png, ...
# The same scenario as a distributed system, one process per agent (lockstep equals
# simulate to the bit); `with` stops whatever is left of it:
#   with swarm.up(repo / "scenarios/case2.toml", clock="lockstep", duration=20) as run:
#       run.wait()                                    # (a lockstep run may end before a live call)
#   distributed = run.results()
#   with swarm.up(repo / "scenarios/case2.toml") as run:  # realtime: live until the block ends
#       print(run.state().graph.edges)                # live, over zenoh
# A finished run directory of `swarm sim` or `swarm up`:
#   again = swarm.open_run("runs/case2")
