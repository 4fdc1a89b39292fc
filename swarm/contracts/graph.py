"""The communication graph as the agents chose it: pure analysis, no I/O.

Edges i -> out[i]. Leaders are sinks. Reports, for `swarm graph` and the summary:
weakly connected components, each follower's root leader and hops, followers with no
path to a leader, and follower-only cycles (the paper's Assumption 1 broken).
"""

from __future__ import annotations


def analyse(out: dict[int, int | None], leaders: set[int], alive: set[int] | None = None) -> dict:
    """out: agent id -> chosen out-neighbour (None: none). alive: live agents (default all).

    Edges to agents that are not alive are kept but reported as `dangling`.
    """
    nodes = set(out) if alive is None else set(alive)
    edges = [(i, j) for i, j in sorted(out.items()) if i in nodes and j is not None]
    succ = {i: j for i, j in edges}
    roots: dict[int, dict] = {}
    cycles: list[list[int]] = []
    seen_cycle: set[int] = set()
    for i in sorted(nodes):
        path: list[int] = []
        cur: int | None = i
        while cur is not None and cur in nodes and cur not in leaders and cur not in path:
            path.append(cur)
            cur = succ.get(cur)
        if cur is not None and cur in leaders and cur in nodes:
            roots[i] = {"root": cur, "hops": len(path)}
        else:
            roots[i] = {"root": None, "hops": None}
            if cur is not None and cur in path:  # a cycle among followers
                cyc = path[path.index(cur) :]
                if not seen_cycle & set(cyc):
                    k = cyc.index(min(cyc))
                    cycles.append(cyc[k:] + cyc[:k])
                    seen_cycle |= set(cyc)
    # weakly connected components over live nodes
    adj: dict[int, set[int]] = {i: set() for i in nodes}
    for i, j in edges:
        if j in nodes:
            adj[i].add(j)
            adj[j].add(i)
    comps, done = [], set()
    for i in sorted(nodes):
        if i in done:
            continue
        stack, comp = [i], []
        done.add(i)
        while stack:
            n = stack.pop()
            comp.append(n)
            for m in adj[n]:
                if m not in done:
                    done.add(m)
                    stack.append(m)
        comps.append(sorted(comp))
    return {
        "nodes": sorted(nodes),
        "leaders": sorted(leaders & nodes),
        "edges": [[i, j] for i, j in edges],
        "dangling": [[i, j] for i, j in edges if j not in nodes],
        "components": comps,
        "roots": {str(i): r for i, r in roots.items()},
        "unrooted": sorted(i for i, r in roots.items() if r["root"] is None and i not in leaders),
        "cycles": cycles,
    }
