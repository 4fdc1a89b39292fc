"""Laws of one's own through the batch engine: a follower law that declares it is vectorised.

A follower law of the older signature, `law(g_i, g_j, lambda_ij, c1, c2) -> u` named in
`[gains] law`, written with numpy operations that work element by element on floats and on
arrays alike, declares it with an attribute:

    def pursuit(g_i, g_j, lambda_ij, c1, c2):
        return c1 * np.arctan2(np.sin(g_j - g_i), np.cos(g_j - g_i)) + c2 * np.sin(lambda_ij - g_i)
    pursuit.vectorised = True

`swarm sim` and `swarm up` call it with floats, agent by agent; a study runs it through the
batch engine, which calls it with (B, N) arrays where it calls the built-in law (the
arithmetic of swarm.agents.laws.bearing_law), and with floats for a follower that has just
chosen a new out-neighbour. Everything else is the batch engine's: the choice of
out-neighbour, the search while there is nobody to follow, the turn-rate limit, the
leaders. A `[law] follower` or `[law] leader` law (law(obs)) is Python per agent and is not
batched.

The batch engine (swarm/offline/batch.py, swarm/agents/batch.py `follower_law_of`) runs such a
law itself, as `swarm sim --batch` does.
"""

from __future__ import annotations

from collections.abc import Callable

from swarm.agents.batch import vectorised
from swarm.contracts.laws import GAINS, resolve_law
from swarm.contracts.scenario import Scenario
from swarm.offline.batch import run_batch
from swarm.world.recording import RunResult

VectorLaw = Callable[..., object]


def batch_law(s: Scenario) -> VectorLaw | None:
    """The scenario's follower law if it is one of one's own declared vectorised
    (`[gains] law` naming a function with `vectorised = True`), else None."""
    if s.gains.law == "bearing":
        return None
    law = resolve_law(s.gains.law, GAINS)
    return law if vectorised(law) else None


def run_batch_with_law(scenarios: list[Scenario], law: VectorLaw) -> list[RunResult]:
    """run_batch (lean) of scenarios whose `[gains] law` is the vectorised `law`: the
    batch engine with `law` in the built-in law's place. Each result's scenario is its own
    (naming `law`)."""
    assert all(batch_law(s) is law for s in scenarios), "scenarios of one vectorised law"
    return run_batch(scenarios, lean=True)
