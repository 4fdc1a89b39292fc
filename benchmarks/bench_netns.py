"""Lockstep ticks/s of one run with its agents on other "machines" (network namespaces, veth
links, `swarm host`) against the same run on one machine over Unix sockets (`swarm up`).

    sudo python benchmarks/bench_netns.py [--n 20] [--seconds 30] [--repeat 2]
                                          [--variants up,veth-tls,veth-tcp,local-hosts] [--json FILE]

The same generated scenario (benchmarks/bench_runtime.py's ring: N agents, 2 leaders,
`nearest` selection, dt 0.01, lockstep) runs as:

- `up`: `swarm up` (world and agents on Unix sockets, one machine: the reference);
- `veth-tls` / `veth-tcp`: the world in namespace `w`, listening on `tls/` (or `tcp/`)
  10.213.0.1, and `swarm host` in namespaces `a` and `b`, half of the agents each, with
  credentials from `swarm credentials --host` (tests/process/test_multihost.py's `Lan`: a bridge
  in `w`, one veth pair per host);
- `local-hosts`: the world on a Unix socket and the two `swarm host` routers on this
  machine (Unix sockets too): what the router hop costs without any network.

ticks/s is the world's own (summary.json: ticks over the wall time from the start, every
agent joined, to the end). Every variant runs --repeat times, interleaved, each after
waiting (up to --quiet-wait s) for the machine to quieten; the table shows the best run
of each (the least disturbed on a shared 2-core machine) and every run, and the ratio to
`up`. Only processes started here are signalled; the namespaces are deleted at the end.
Needs root (network namespaces); without it, only `up` and `local-hosts` run.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
sys.path[:0] = [str(REPO), str(BENCH), str(REPO / "tests")]

from bench_runtime import Tracked, log, scenario_toml, wait_quiet  # noqa: E402
from test_multihost import Lan, LanError, why_no_lan  # noqa: E402

from swarm.contracts.vocabulary import ExitCode  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402

PY = sys.executable
VARIANTS = ("up", "veth-tls", "veth-tcp", "local-hosts")
HOSTS = ("a", "b")


def swarm(*args) -> list[str]:
    return [PY, "-m", "swarm", *map(str, args)]


def env_for(runtime_dir: str) -> dict:
    return {**os.environ, "SWARM_RUNTIME_DIR": runtime_dir, "PYTHONUNBUFFERED": "1"}


def halves(n: int) -> dict[str, str]:
    cut = (n + 1) // 2
    return {"a": f"1-{cut}", "b": f"{cut + 1}-{n}"}


def summary_of(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def run_up(scen: Path, work: Path, tag: str, timeout: float) -> dict:
    out, rt = work / f"up-{tag}", tempfile.mkdtemp(prefix="swn", dir="/tmp")
    tr = Tracked()
    try:
        t0 = time.monotonic()
        p = tr.spawn(
            swarm("up", scen, "--out", out, "--no-plots", "--clock", "lockstep"), work / f"up-{tag}.log", env_for(rt)
        )
        if not wait_until(lambda: p.poll() is not None, timeout, 0.1) or p.returncode != ExitCode.OK:
            raise RuntimeError(f"swarm up exited {p.poll()}; see {work / f'up-{tag}.log'}")
        s = summary_of(out)
        return {
            "ticks_per_second": s["ticks_per_second"],
            "ticks": s["ticks"],
            "wall_s": time.monotonic() - t0,
            "ticking_s": s["wall_time"],
        }
    finally:
        tr.stop()
        shutil.rmtree(rt, ignore_errors=True)


def run_hosts(scen: Path, n: int, work: Path, tag: str, timeout: float, lan: Lan | None, proto: str) -> dict:
    """The world and two `swarm host`s: in the namespaces of `lan` over `proto`, or (lan None)
    all on this machine over Unix sockets."""
    run = f"bn-{tag}"
    dirs = {k: tempfile.mkdtemp(prefix="swn", dir="/tmp") for k in ("w", *HOSTS)}
    out = work / f"world-{tag}"
    tr = Tracked()

    def where(k: str, args: list[str]) -> list[str]:
        return lan.cmd(k, args) if lan is not None else args

    try:
        t0 = time.monotonic()
        listen = f"{proto}/{lan.address['w']}:7447" if lan is not None else f"unixsock-stream/{dirs['w']}/w.sock"
        world = tr.spawn(
            where(
                "w",
                swarm(
                    "world", scen, "--listen", listen, "--run", run, "--clock", "lockstep", "--out", out, "--no-plots"
                ),
            ),
            work / f"world-{tag}.log",
            env_for(dirs["w"]),
        )
        cred = Path(dirs["w"]) / f"{run}.cred"
        if not wait_until(lambda: cred.exists() or world.poll() is not None, 30, 0.05) or world.poll() is not None:
            raise RuntimeError(f"the world did not start; see {work / f'world-{tag}.log'}")
        hosts = []
        for h, ids in halves(n).items():
            if lan is not None:
                f = work / f"host-{h}-{tag}.cred"
                p = tr.spawn(
                    swarm("credentials", "--host", h, "--agents", ids, "--run", run, "-o", f, "--force"),
                    work / f"credentials-{tag}.log",
                    env_for(dirs["w"]),
                )
                if p.wait(30) != ExitCode.OK:
                    raise RuntimeError(f"swarm credentials failed; see {work / f'credentials-{tag}.log'}")
                args = swarm("host", "--credentials", f, "--logs", work / f"logs-{h}-{tag}")
                env = env_for(dirs[h])
            else:  # the run's own credentials, found in the world's runtime dir
                args = swarm("host", "--run", run, "--agents", ids, "--name", h, "--logs", work / f"logs-{h}-{tag}")
                env = env_for(dirs["w"])
            hosts.append(tr.spawn(where(h, args), work / f"host-{h}-{tag}.log", env))
        procs = [world, *hosts]
        if not wait_until(lambda: all(p.poll() is not None for p in procs), timeout, 0.1):
            raise RuntimeError(f"run {tag} did not end within {timeout:g} s")
        codes = [p.returncode for p in procs]
        if any(codes):
            raise RuntimeError(f"run {tag}: exit codes world {codes[0]}, hosts {codes[1:]}; logs in {work}")
        s = summary_of(out)
        return {
            "ticks_per_second": s["ticks_per_second"],
            "ticks": s["ticks"],
            "wall_s": time.monotonic() - t0,
            "ticking_s": s["wall_time"],
            "missed": sum(a["missed_ticks"] for a in s["agents"].values()),
        }
    finally:
        tr.stop()
        for d in dirs.values():
            shutil.rmtree(d, ignore_errors=True)


def report(results: dict, n: int) -> str:
    ref = results.get("up")
    ref_best = max((r["ticks_per_second"] for r in ref), default=None) if ref else None
    lines = [
        f"lockstep ticks/s, {n} agents, best of {max(len(v) for v in results.values())} (the other runs in brackets)",
        f"{'variant':<12} {'ticks/s':>8} {'vs up':>6}  {'runs':<24} {'wall s (ticking)':<18}",
    ]
    for variant, runs in results.items():
        if not runs:
            continue
        best = max(runs, key=lambda r: r["ticks_per_second"])
        ratio = f"{best['ticks_per_second'] / ref_best:.2f}" if ref_best else "-"
        others = ", ".join(f"{r['ticks_per_second']:.0f}" for r in runs if r is not best)
        lines.append(
            f"{variant:<12} {best['ticks_per_second']:8.0f} {ratio:>6}  [{others}]".ljust(54)
            + f"{best['wall_s']:.1f} ({best['ticking_s']:.1f})"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=20, help="agents (half on each host)")
    ap.add_argument("--seconds", type=float, default=30.0, help="simulated seconds per run (dt 0.01)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--quiet-wait", type=float, default=20.0, help="s to wait at most for a quiet machine")
    ap.add_argument("--json", type=Path, default=None)
    ap.add_argument("--keep", action="store_true", help="keep the work directory (logs, results)")
    a = ap.parse_args(argv)
    variants = [v for v in a.variants.split(",") if v]
    unknown = set(variants) - set(VARIANTS)
    if unknown:
        ap.error(f"unknown variants {sorted(unknown)}; choose from {', '.join(VARIANTS)}")
    why = why_no_lan()
    if why and any(v.startswith("veth") for v in variants):
        log(f"skipping the veth variants: {why}")
        variants = [v for v in variants if not v.startswith("veth")]
    work = Path(tempfile.mkdtemp(prefix="bench-netns-"))
    scen = work / f"ring-{a.n}.toml"
    scen.write_text(scenario_toml(a.n, duration=a.seconds))
    timeout = 60 + a.seconds * 100 * 0.05  # 20 ticks/s at worst, plus the start
    lan = None
    results: dict[str, list[dict]] = {v: [] for v in variants}
    failed = True
    try:
        if any(v.startswith("veth") for v in variants):
            try:
                lan = Lan(HOSTS).up()
            except LanError as e:
                log(f"skipping the veth variants: cannot make network namespaces ({e})")
                variants = [v for v in variants if not v.startswith("veth")]
        for k in range(a.repeat):
            for v in variants:
                quiet = wait_quiet(0.3, a.quiet_wait)
                tag = f"{v}-{k}"
                log(f"{tag}: machine busy {quiet['busy_cores']:.2f} cores after {quiet['waited_s']:.0f} s; running")
                if v == "up":
                    r = run_up(scen, work, tag, timeout)
                elif v == "local-hosts":
                    r = run_hosts(scen, a.n, work, tag, timeout, None, "unixsock-stream")
                else:
                    r = run_hosts(scen, a.n, work, tag, timeout, lan, v.split("-")[1])
                r["busy_before"] = quiet["busy_cores"]
                results[v].append(r)
                log(f"{tag}: {r['ticks_per_second']:.0f} ticks/s ({r['ticks']} ticks, {r['wall_s']:.1f} s in all)")
        failed = False
    finally:
        if lan is not None:
            errors = lan.down()
            if errors:
                log(f"warning: {errors}")
        if not (a.keep or failed):
            shutil.rmtree(work, ignore_errors=True)
        else:
            log(f"kept {work}")
    print(report({v: r for v, r in results.items() if r}, a.n))
    if a.json is not None:
        a.json.write_text(json.dumps({"n": a.n, "seconds": a.seconds, "results": results}, indent=1))
    return ExitCode.OK


if __name__ == "__main__":
    sys.exit(main())
