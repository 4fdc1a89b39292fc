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

The batch engine (swarm/offline/batch.py) takes no law as an argument yet: `run_batch_with_law`
puts the law where the batch brains call the built-in one (swarm.agents.batch and
swarm.agents.batch_sticky's `bearing_law`) for the length of one batch, in this process, and
puts the built-in back after.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from swarm.agents import batch as agents_batch
from swarm.agents import batch_sticky
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
    return law if getattr(law, "vectorised", False) is True else None


@contextmanager
def _in_batch(law: VectorLaw) -> Iterator[None]:
    def batched(g_i, g_j, lambda_ij, c1, c2, *, ops=None):  # ops: the built-in law's array switch
        return law(g_i, g_j, lambda_ij, c1, c2)

    mods: tuple[Any, ...] = (agents_batch, batch_sticky)  # modules: their `bearing_law` swapped
    saved = [m.bearing_law for m in mods]
    for m in mods:
        m.bearing_law = batched
    try:
        yield
    finally:
        for m, f in zip(mods, saved):
            m.bearing_law = f


def run_batch_with_law(scenarios: list[Scenario], law: VectorLaw) -> list[RunResult]:
    """run_batch (lean) of scenarios whose `[gains] law` is the vectorised `law`: the
    batch engine with `law` in the built-in law's place. Each result's scenario is its own
    (naming `law`)."""
    plain = [s.model_copy(update={"gains": s.gains.model_copy(update={"law": "bearing"})}) for s in scenarios]
    with _in_batch(law):
        results = run_batch(plain, lean=True)
    for r, s in zip(results, scenarios):
        r.scenario = s
    return results
