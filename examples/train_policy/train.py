"""Train the two gains of policy.py in swarm.env, then run the result as a law under
`swarm sim` and `swarm up --clock lockstep` and compare them (docs/guides/learning.md).

    python examples/train_policy/train.py                       # minutes on 2 cores
    python examples/train_policy/train.py --generations 2 --population 3 --episode 5 --duration 5

A (1 + lambda) evolution strategy on log-gains: each generation draws `population`
mutations of the best gains so far (step size sigma, grown by 1.5 on a success and shrunk
by 0.8 otherwise), scores each by the mean per-agent, per-step reward of the environment
(its default reward: radial and angular-rate error) over the same `episodes` seeded
episodes with jittered starts, and keeps the best. The same episodes every generation
make the score deterministic, so the kept gains never score worse than the initial ones.

Writes gains.json next to policy.py (the gains, and the score of every generation),
then runs scenario.toml with `swarm sim` and `swarm up --clock lockstep` into --out and
prints the largest difference of their trajectories (0 m expected: same engine, same
law, same ticks). Exit 0 when they agree, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from policy import GAINS_FILE, INITIAL, gains_policy

from swarm.env import SwarmEnv

HERE = Path(__file__).resolve().parent
SCENARIO = HERE / "scenario.toml"


def score(gains: tuple[float, float], episode: float, episodes: int, seed: int) -> float:
    """Mean reward per agent and step of the policy of `gains` over `episodes` episodes."""
    policy = gains_policy(*gains)
    env = SwarmEnv(SCENARIO, duration=episode, position_jitter=5.0, heading_jitter=0.3)
    total, count = 0.0, 0
    for n in range(episodes):
        obs, _ = env.reset(seed=seed + n)
        while env.agents:
            obs, rewards, _, _, _ = env.step({a: policy(o) for a, o in obs.items()})
            total += sum(rewards.values())
            count += len(rewards)
    return total / max(count, 1)


def train(args: argparse.Namespace) -> dict:
    rng = np.random.default_rng(args.seed)
    best = INITIAL
    args_score = (args.episode, args.episodes, args.seed)
    best_score = score(best, *args_score)
    sigma = args.sigma
    history = [{"generation": 0, "gains": list(best), "reward": best_score, "sigma": sigma}]
    print(f"generation 0: gains k1 = {best[0]:.4f}, k2 = {best[1]:.4f}, reward {best_score:.4f}")
    with ProcessPoolExecutor(args.workers) as pool:
        for g in range(1, args.generations + 1):
            logs = np.log(best) + sigma * rng.standard_normal((args.population, 2))
            candidates = [(float(a), float(b)) for a, b in np.exp(logs)]
            scores = list(pool.map(score, candidates, *([v] * len(candidates) for v in args_score)))
            k = int(np.argmax(scores))
            if scores[k] > best_score:
                best, best_score, sigma = candidates[k], scores[k], sigma * 1.5
            else:
                sigma *= 0.8
            history.append({"generation": g, "gains": list(best), "reward": best_score, "sigma": sigma})
            print(
                f"generation {g}: gains k1 = {best[0]:.4f}, k2 = {best[1]:.4f}, reward {best_score:.4f}"
                f" (candidates {min(scores):.4f} .. {max(scores):.4f})"
            )
    return {"gains": list(best), "history": history}


def run(cmd: list[str]) -> None:
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)


def up_equals_sim(out: Path, duration: float) -> float:
    """Run scenario.toml (the trained law) with swarm sim and lockstep swarm up; the
    largest |dx|, |dy| between their trajectories (m)."""
    swarm = [sys.executable, "-m", "swarm"]
    d = ["--duration", str(duration), "--force"]
    run([*swarm, "sim", str(SCENARIO), "--out", str(out / "sim"), "--no-plots", *d])
    run([*swarm, "up", str(SCENARIO), "--out", str(out / "up"), "--clock", "lockstep", "--no-plots", *d])
    sim, up = np.load(out / "sim" / "trajectory.npz"), np.load(out / "up" / "trajectory.npz")
    if sim["x"].shape != up["x"].shape:
        return math.inf
    return float(max(np.abs(sim["x"] - up["x"]).max(), np.abs(sim["y"] - up["y"]).max()))


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--generations", type=int, default=8)
    p.add_argument("--population", type=int, default=6, help="candidates per generation")
    p.add_argument("--episode", type=float, default=30.0, help="simulated seconds of a training episode")
    p.add_argument("--episodes", type=int, default=2, help="episodes per score")
    p.add_argument("--sigma", type=float, default=0.5, help="initial step on log-gains")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--workers", type=int, default=2, help="processes scoring candidates")
    p.add_argument("--duration", type=float, default=60.0, help="simulated seconds of the sim/up runs")
    p.add_argument("--out", type=Path, default=Path("runs/train_policy"), help="where the sim/up runs go")
    args = p.parse_args(argv)
    t0 = time.monotonic()
    trained = train(args)
    GAINS_FILE.write_text(json.dumps(trained, indent=2) + "\n")
    print(f"wrote {GAINS_FILE} ({time.monotonic() - t0:.1f} s of training)")
    diff = up_equals_sim(args.out, args.duration)
    print(f"lockstep swarm up vs swarm sim, {args.duration:g} s: max |dx|, |dy| = {diff:g} m")
    return 0 if diff == 0.0 else 1


if __name__ == "__main__":
    sys.exit(main())
