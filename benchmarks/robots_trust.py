"""Trust on the robots' network (docs/guides/robots.md#trust): a stranger on the robots' router
during a run of scenarios/turtlebot.toml against the simulated fleet (`swarm robots sim`).

The stranger is a zenoh client with no credentials that speaks rmw_zenoh (a ROS node
`/intruder` with its own publishers, as any ROS 2 process would): `--rate` Hz for `--seconds`
s it publishes nav_msgs/Odometry on robot 1's pose topic (a pose metres away from the robot)
and twists on robot 1's cmd_vel (full speed, full turn). Three runs of `--duration` s each:

  open     the fleet's router open to anyone (rmw_zenohd's default), the stranger on it;
  copycat  the open router, a stranger with no token in the graph that copies the GIDs of the
           robot's poses and of the world's commands from their attachments;
  closed   the router closed with usrpwd and an ACL (`--router-config`, what rmw_zenohd
           accepts), the world joining with the robots file's user and password_file; the
           stranger tries to connect without credentials;
  clean    the open router, no stranger: the reference run.

Prints per run: the largest jump of agent 1's recorded pose in one tick (m), the commands
robot 1 received (the fleet's report) against the twists the world sent it, the poses the
world refused (foreign: another publisher's GID; implausible: beyond the robot's limits) and
malformed, every world log line that names the stranger with its delay from the stranger's
first sample, and the follower's final radius and mean [min, max] over the last 10 s.

    python benchmarks/robots_trust.py                      # about 2 min of wall time
    python benchmarks/robots_trust.py --runs open          # one run
    python benchmarks/robots_trust.py --swarm-root DIR     # the world and fleet of another checkout (before/after)

`--swarm-root` puts another checkout first on the processes' PYTHONPATH (e.g. a `git worktree`
of an older commit): the stranger and this script stay this checkout's.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from swarm.contracts.scenario import load_scenario  # noqa: E402
from swarm.runtime.procs import wait_until  # noqa: E402

USER, PASSWORD = "swarm", "robots-bench-password"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def robots_file(src: Path, endpoint: str, out: Path, credentials: Path | None) -> Path:
    """A copy of `src` on `endpoint`, with the user and password file of the closed router."""
    text = re.sub(r'(?m)^connect\s*=\s*"[^"]*"', f'connect = "{endpoint}"', src.read_text())
    if credentials is not None:
        text = text.replace("[ros2]\n", f'[ros2]\nuser = "{USER}"\npassword_file = "{credentials}"\n', 1)
    out.write_text(text)
    return out


def router_config(work: Path) -> Path:
    """A zenoh router config as rmw_zenohd takes it (ZENOH_ROUTER_CONFIG_URI): usrpwd from a
    dictionary file, and an ACL that lets only the user `swarm` in, on ROS domain 0's keys."""
    dictionary = work / "users.txt"
    dictionary.write_text(f"{USER}:{PASSWORD}\n")
    dictionary.chmod(0o600)
    messages = [
        "put",
        "delete",
        "declare_subscriber",
        "query",
        "declare_queryable",
        "reply",
        "liveliness_token",
        "declare_liveliness_subscriber",
        "liveliness_query",
    ]
    config = {
        "transport": {"auth": {"usrpwd": {"dictionary_file": str(dictionary)}}},
        "access_control": {
            "enabled": True,
            "default_permission": "deny",
            "rules": [
                {
                    "id": "ros-domain-0",
                    "permission": "allow",
                    "flows": ["ingress", "egress"],
                    "messages": messages,
                    "key_exprs": ["0/**", "@ros2_lv/0/**"],
                }
            ],
            "subjects": [{"id": "fleet-users", "usernames": [USER]}],
            "policies": [{"rules": ["ros-domain-0"], "subjects": ["fleet-users"]}],
        },
    }
    path = work / "router.json5"
    path.write_text(json.dumps(config, indent=2))
    return path


# -- the stranger (a subprocess: no zenoh session in this process, which starts the others) -------
def stranger(connect: str, namespace: str, rate: float, seconds: float, out: Path) -> int:
    import zenoh

    from swarm.contracts.transport import client_config
    from swarm.ros2 import cdr
    from swarm.ros2.node import Ros2Node
    from swarm.ros2.types import ODOMETRY, TWIST

    note = {"connect": connect, "opened": False}
    try:
        session = zenoh.open(client_config(connect, timeout_ms=3000))
    except Exception as e:  # the closed router refuses it
        note["refused"] = str(e).split(" at /", 1)[0]
        out.write_text(json.dumps(note))
        return 3
    note["opened"] = True
    try:
        with Ros2Node(session, "intruder") as node:
            note["declared_wall"] = time.time()  # its publishers' tokens go out now
            pose = node.publisher(f"{namespace}/odom", ODOMETRY)
            cmd = node.publisher(f"{namespace}/cmd_vel", TWIST)
            time.sleep(0.5)  # its tokens reach the router
            note["first_sample_wall"] = time.time()
            t0, n = time.monotonic(), 0
            while time.monotonic() - t0 < seconds:
                pose.put(cdr.encode_odometry(time.time_ns(), "odom", "base_footprint", 4.0, 5.0, 0.0))
                cmd.put(cdr.encode_twist(0.22, 2.84))
                n += 1
                time.sleep(max(0.0, t0 + n / rate - time.monotonic()))
            note["samples"] = n
            note["gid"] = pose.gid.hex()
    finally:
        session.close()
    out.write_text(json.dumps(note))
    return 0


def copycat(connect: str, namespace: str, rate: float, seconds: float, out: Path) -> int:
    """A stranger that copies GIDs: no token in the graph; it reads the robot's pose attachment
    and our world's command attachment, then publishes with their GIDs."""
    import zenoh

    from swarm.contracts.transport import client_config
    from swarm.ros2 import cdr
    from swarm.ros2.attachment import attachment, parse_attachment

    note: dict = {"connect": connect, "opened": True, "copycat": True}
    session = zenoh.open(client_config(connect, timeout_ms=3000))
    seen: dict[str, tuple[str, int, bytes]] = {}  # topic -> (key, seq, gid)

    def grab(topic: str):
        def on(sample: zenoh.Sample) -> None:
            if sample.attachment is not None and topic not in seen:
                seq, _, gid = parse_attachment(sample.attachment.to_bytes())
                seen[topic] = (str(sample.key_expr), seq, gid)

        return on

    ns = namespace.strip("/")
    subs = [session.declare_subscriber(f"0/{ns}/{t}/*/*", grab(t)) for t in ("odom", "cmd_vel")]
    try:
        wait_until(lambda: len(seen) == 2, 10, 0.01)
        (pose_key, pose_seq, pose_gid), (cmd_key, cmd_seq, cmd_gid) = seen["odom"], seen["cmd_vel"]
        pose_pub, cmd_pub = session.declare_publisher(pose_key), session.declare_publisher(cmd_key)
        note["first_sample_wall"] = time.time()
        t0, n = time.monotonic(), 0
        while time.monotonic() - t0 < seconds:
            n += 1
            now = time.time_ns()
            pose_pub.put(
                cdr.encode_odometry(now, "odom", "base_footprint", 4.0, 5.0, 0.0),
                attachment=attachment(pose_seq + n, now, pose_gid),
            )
            cmd_pub.put(cdr.encode_twist(0.22, 2.84), attachment=attachment(cmd_seq + 10_000 + n, now, cmd_gid))
            time.sleep(max(0.0, t0 + n / rate - time.monotonic()))
        note["samples"] = n
        note["gid"] = pose_gid.hex()
    finally:
        for sub in subs:
            sub.undeclare()
        session.close()
    out.write_text(json.dumps(note))
    return 0


# -- one run ----------------------------------------------------------------------------------------
def one_run(name: str, args: argparse.Namespace, work: Path) -> dict:
    d = work / name
    d.mkdir()
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    closed = name == "closed"
    credentials = None
    if closed:
        credentials = d / "password"
        credentials.write_text(PASSWORD + "\n")
        credentials.chmod(0o600)
    robots = robots_file(args.robots, endpoint, d / "robots.toml", credentials)
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    if args.swarm_root is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(args.swarm_root), env.get("PYTHONPATH", "")])
    swarm_cmd = [sys.executable, "-m", "swarm"]
    fleet_cmd = [*swarm_cmd, "robots", "sim", str(args.scenario), "--robots", str(robots), "--latency", "0.03"]
    fleet_cmd += ["--pose-noise", "0.005"]
    if closed:
        fleet_cmd += ["--router-config", str(router_config(d))]
    out = d / "run"
    up_cmd = [*swarm_cmd, "up", str(args.scenario), "--robots", str(robots), "--duration", str(args.duration)]
    up_cmd += ["--out", str(out), "--no-plots", "--force"]
    fleet_log, up_log, note_path = d / "fleet.log", d / "up.log", d / "stranger.json"
    world_log = out / "logs" / "world.log"
    seen: list[tuple[float, str]] = []  # (wall s, line) of world log lines naming the stranger
    fleet = subprocess.Popen(
        fleet_cmd, stdout=open(fleet_log, "w"), stderr=subprocess.STDOUT, env=env, start_new_session=True
    )
    stranger_proc = None
    try:
        if not wait_until(lambda: fleet.poll() is not None or "fleet ready" in fleet_log.read_text(), 60, 0.1):
            raise SystemExit(f"{name}: the fleet did not get ready within 60 s")
        if fleet.poll() is not None:
            raise SystemExit(f"{name}: the fleet exited ({fleet.returncode}):\n{fleet_log.read_text()}")
        up = subprocess.Popen(up_cmd, stdout=open(up_log, "w"), stderr=subprocess.STDOUT, env=env)
        started = None
        offset = 0
        while up.poll() is None:
            now = time.time()
            if world_log.exists():
                text = world_log.read_text(errors="replace")
                for line in text[offset:].splitlines(keepends=True):
                    if not line.endswith("\n"):
                        break
                    offset += len(line)
                    if re.search(r"intruder|another publisher|other publisher|refused|GID", line):
                        seen.append((now, line.strip()))
                if started is None and re.search(r"robot 2: ", text):
                    started = time.monotonic()
            if (
                name != "clean"
                and started is not None
                and stranger_proc is None
                and time.monotonic() - started >= args.stranger_at
            ):
                stranger_proc = subprocess.Popen(
                    [
                        sys.executable,
                        __file__,
                        "--stranger",
                        endpoint,
                        "--rate",
                        str(args.rate),
                        "--seconds",
                        str(args.seconds),
                        "--note",
                        str(note_path),
                        *(["--copycat"] if name == "copycat" else []),
                    ],
                    stdout=subprocess.DEVNULL,
                    stderr=subprocess.STDOUT,
                    env={**os.environ, "PYTHONUNBUFFERED": "1"},
                )
            time.sleep(0.01)
    finally:
        if stranger_proc is not None:
            stranger_proc.wait(30)
        if fleet.poll() is None:
            fleet.send_signal(signal.SIGINT)
        try:
            fleet.wait(30)
        except subprocess.TimeoutExpired:
            fleet.kill()
            fleet.wait()
    note = json.loads(note_path.read_text()) if note_path.exists() else {}
    summary = json.loads((out / "summary.json").read_text())
    scenario = load_scenario(args.scenario)
    with np.load(out / "trajectory.npz") as z:
        t, x, y, ids = z["t"], z["x"], z["y"], [int(i) for i in z["ids"]]
    k1, k2 = ids.index(1), ids.index(2)
    jumps = np.hypot(np.diff(x[:, k1]), np.diff(y[:, k1]))
    radius = np.hypot(x[:, k2] - scenario.target.x, y[:, k2] - scenario.target.y)
    tail = t >= t[-1] - 10.0
    report = {
        int(m.group(1)): int(m.group(2)) for m in re.finditer(r"robot (\d+): (\d+) commands", fleet_log.read_text())
    }
    robot1 = summary.get("robots", {}).get("agents", {}).get("1", {})
    first = note.get("first_sample_wall")
    return {
        "run": name,
        "up_exit": up.returncode,
        "stranger": note,
        "max_jump_agent1_m": float(np.nanmax(jumps)),
        "robot1_commands_received": report.get(1),
        "robot1_twists_sent_by_world": robot1.get("twists"),
        "robot1_poses": robot1.get("poses"),
        "robot1_malformed": robot1.get("malformed_poses"),
        "robot1_refused": robot1.get("refused_poses"),
        "robot1_foreign_commands": robot1.get("foreign_commands"),
        "robot1_other_publishers": robot1.get("other_publishers"),
        "robot2_malformed": summary.get("robots", {}).get("agents", {}).get("2", {}).get("malformed_poses"),
        "refusals": summary.get("robots", {}).get("refusals"),
        "log_lines": [(round(w - first, 3) if first else None, line) for w, line in seen],
        "graph_notice_after_tokens_s": next(
            (round(w - note["declared_wall"], 3) for w, line in seen if "another publisher on" in line), None
        )
        if "declared_wall" in note
        else None,
        "follower_final_m": float(radius[-1]),
        "follower_tail_m": [float(radius[tail].mean()), float(radius[tail].min()), float(radius[tail].max())],
        "terminal": [
            line for line in up_log.read_text().splitlines() if line.startswith(("robots:", "converged", "warning"))
        ],
    }


def show(r: dict) -> None:
    print(f"\n== {r['run']} (swarm up exit {r['up_exit']})")
    s = r["stranger"]
    if s:
        if s.get("opened"):
            print(f"  stranger: connected, {s.get('samples')} samples of each at {s.get('gid', '')[:8]}...")
        else:
            print(f"  stranger: refused at connect: {s.get('refused')}")
    print(f"  agent 1: largest jump in one tick {r['max_jump_agent1_m']:.3f} m")
    print(
        f"  robot 1: received {r['robot1_commands_received']} commands, "
        f"the world sent {r['robot1_twists_sent_by_world']}"
    )
    print(
        f"  robot 1 poses: {r['robot1_poses']} accepted, refused {r['robot1_refused']}, "
        f"malformed {r['robot1_malformed']}"
        f" (robot 2 malformed {r['robot2_malformed']}); foreign commands seen {r['robot1_foreign_commands']}"
    )
    print(f"  other publishers named: {r['robot1_other_publishers']}; refusals in summary: {r['refusals']}")
    if r["graph_notice_after_tokens_s"] is not None:
        print(f"  the stranger named in the log {r['graph_notice_after_tokens_s']} s after its tokens went out")
    for delay, line in r["log_lines"][:6]:
        print(f"  log (+{delay} s after the stranger's first sample): {line}")
    if not r["log_lines"]:
        print("  log: nothing names the stranger")
    for line in r["terminal"]:
        print(f"  terminal: {line}")
    lo, mn, mx = r["follower_tail_m"][1], r["follower_tail_m"][0], r["follower_tail_m"][2]
    print(f"  follower radius: final {r['follower_final_m']:.4f} m, last 10 s {mn:.4f} [{lo:.4f}, {mx:.4f}]")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", type=Path, default=ROOT / "scenarios" / "turtlebot.toml")
    ap.add_argument("--robots", type=Path, default=ROOT / "scenarios" / "robots" / "turtlebot.toml")
    ap.add_argument("--duration", type=float, default=30.0, help="run seconds of each run (default 30)")
    ap.add_argument("--stranger-at", type=float, default=10.0, help="s after the world is ready (default 10)")
    ap.add_argument("--rate", type=float, default=100.0, help="the stranger's samples per second (default 100)")
    ap.add_argument("--seconds", type=float, default=5.0, help="how long the stranger publishes (default 5)")
    ap.add_argument("--runs", default="open,copycat,closed,clean", help="which runs, comma-separated")
    ap.add_argument("--swarm-root", type=Path, default=None, help="another checkout's swarm for the world and fleet")
    ap.add_argument("--json", type=Path, default=None, help="also write the figures there")
    ap.add_argument("--stranger", default=None, help=argparse.SUPPRESS)
    ap.add_argument("--note", type=Path, default=None, help=argparse.SUPPRESS)
    ap.add_argument("--namespace", default="/tb3_0", help=argparse.SUPPRESS)
    ap.add_argument("--copycat", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.stranger is not None and args.copycat:
        return copycat(args.stranger, args.namespace, args.rate, args.seconds, args.note)
    if args.stranger is not None:
        return stranger(args.stranger, args.namespace, args.rate, args.seconds, args.note)
    work = Path(tempfile.mkdtemp(prefix="robots-trust-"))
    print(f"work dir: {work}")
    results = []
    for name in args.runs.split(","):
        r = one_run(name, args, work)
        show(r)
        results.append(r)
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
