"""`swarm robots sim`: a simulated fleet of ROS 2 robots that speak rmw_zenoh (swarm/robots/fleet.py),
to rehearse a hardware run on one machine (docs/guides/robots.md)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Optional

import typer

from swarm.cli.errors import fail
from swarm.cli.options import ScenarioArg
from swarm.contracts.vocabulary import ExitCode

robots_app = typer.Typer(
    help="Real robots through ROS 2 (rmw_zenoh): a simulated fleet to rehearse on.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def parse_stop_poses(values: list[str]) -> dict[int, float]:
    """["2:5", "3:7.5"] -> {2: 5.0, 3: 7.5}; a usage error naming the option otherwise."""
    out = {}
    for text in values:
        agent, sep, at = text.partition(":")
        try:
            if not sep:
                raise ValueError
            out[int(agent)] = seconds = float(at)
        except ValueError:
            raise fail(f"--stop-poses {text}: give AGENT:SECONDS, e.g. 2:5", ExitCode.USAGE) from None
        if not (seconds >= 0.0 and math.isfinite(seconds)):
            raise fail(f"--stop-poses {text}: SECONDS must be a finite number >= 0", ExitCode.USAGE)
    return out


@robots_app.command("sim")
def sim(
    scenario: ScenarioArg,
    robots: Annotated[
        Path,
        typer.Option("--robots", help="the robots file (which robot each agent drives)", show_default=False),
    ],
    listen: Annotated[
        Optional[str],
        typer.Option(
            help="where the fleet's router listens (default: the robots file's ros2.connect)", show_default=False
        ),
    ] = None,
    latency: Annotated[float, typer.Option(help="s from a pose's measurement to its publication", min=0.0)] = 0.0,
    pose_noise: Annotated[float, typer.Option(help="m: standard deviation of the noise on x and y", min=0.0)] = 0.0,
    yaw_noise: Annotated[
        Optional[float],
        typer.Option(help="rad: of the noise on the yaw (default: --pose-noise / 0.2 m)", min=0.0, show_default=False),
    ] = None,
    rate: Annotated[float, typer.Option(help="Hz: poses per second per robot", min=0.1)] = 30.0,
    cmd_timeout: Annotated[
        float, typer.Option(help="s: a robot whose last command is older stops (its watchdog)", min=0.0)
    ] = 0.5,
    time_scale: Annotated[
        float,
        typer.Option(
            "--time-scale",
            help="fleet seconds per wall second (the same as swarm up's --time-scale); "
            "--latency, --rate and --cmd-timeout are in fleet seconds",
            min=1e-6,
        ),
    ] = 1.0,
    seed: Annotated[int, typer.Option(help="the pose noise's seed")] = 0,
    quantize: Annotated[
        float,
        typer.Option(
            help="m/s and rad/s: each command truncated toward zero to whole steps, as a TurtleBot3's "
            "turtlebot3_node does (0.01); 0: none",
            min=0.0,
        ),
    ] = 0.0,
    router_config: Annotated[
        Optional[Path],
        typer.Option(
            help="a zenoh config file (JSON5) for the fleet's router, as rmw_zenohd takes it "
            "(ZENOH_ROUTER_CONFIG_URI): e.g. transport/auth/usrpwd and access_control to close it",
            show_default=False,
        ),
    ] = None,
    duration: Annotated[
        Optional[float],
        typer.Option(help="stop after this many fleet seconds (default: at Ctrl-C)", min=0.0, show_default=False),
    ] = None,
    stop_poses: Annotated[
        Optional[list[str]],
        typer.Option(
            help="AGENT:SECONDS: that robot stops publishing its poses SECONDS (fleet time) after the fleet's "
            "first motion command, the run's start (rehearses stale poses; repeatable)",
            show_default=False,
        ),
    ] = None,
) -> None:
    """Simulated robots that speak ROS 2 over rmw_zenoh, at the scenario's start poses.

    One process: a zenoh router standing in for the robots' rmw_zenohd (on the robots file's
    ros2.connect, or --listen) and, per robot of the robots file, a ROS node in its
    namespace that subscribes to its command topic (Twist, or TwistStamped when the robots
    file says so) and publishes its pose (Odometry relative to its start, or PoseStamped in
    the world frame for mocap). Each robot is a unicycle that follows its last command,
    saturated at its max_linear and max_angular, and stops when that command is older than
    --cmd-timeout.

    Exit codes: 0 --duration reached, 2 bad options, scenario or robots file, or the router
    cannot listen, 130/143 stopped by Ctrl-C/SIGTERM.

    Example: swarm robots sim scenarios/turtlebot.toml --robots scenarios/robots/turtlebot.toml --latency 0.03
    --pose-noise 0.01, then swarm up scenarios/turtlebot.toml --robots scenarios/robots/turtlebot.toml
    """
    # lazy: zenoh, the scenario and robots models and the fleet, which `swarm --help` must not pay
    from swarm.contracts.scenario import load_scenario
    from swarm.robots.config import check_against, load_robots
    from swarm.robots.fleet import FleetOptions, run_fleet

    spec = load_scenario(scenario)
    fleet_robots = load_robots(robots)
    for warning in check_against(fleet_robots, spec, str(robots)):
        typer.secho(f"warning: {warning}", err=True, fg=typer.colors.YELLOW)
    try:
        options = FleetOptions(
            latency=latency,
            pose_noise=pose_noise,
            yaw_noise=yaw_noise,
            rate=rate,
            cmd_timeout=cmd_timeout,
            time_scale=time_scale,
            seed=seed,
            quantize=quantize,
            stop_poses=parse_stop_poses(stop_poses or []),
        )
    except ValueError as e:
        raise fail(str(e), ExitCode.USAGE) from None
    if router_config is not None and not router_config.is_file():
        raise fail(f"--router-config {router_config}: no such file", ExitCode.USAGE)
    config_file = str(router_config) if router_config is not None else None
    raise typer.Exit(run_fleet(fleet_robots, spec, options, listen=listen, duration=duration, config_file=config_file))


@robots_app.command("guard")
def guard(
    robots: Annotated[
        Path,
        typer.Option("--robots", help="the robots file (the robots to guard)", show_default=False),
    ],
    connect: Annotated[
        Optional[str],
        typer.Option(
            help="the robots' router from this machine (default: the robots file's guard.connect, else ros2.connect)",
            show_default=False,
        ),
    ] = None,
    cmd_timeout: Annotated[
        Optional[float],
        typer.Option(
            help="s without a command before a moving robot gets a zero twist (default: the robots file's "
            "guard.cmd_timeout, 0.5)",
            min=0.001,
            max=60.0,
            show_default=False,
        ),
    ] = None,
    duration: Annotated[
        Optional[float],
        typer.Option(help="stop after this many s (default: at Ctrl-C)", min=0.0, show_default=False),
    ] = None,
) -> None:
    """Zero-twist every robot whose commands stopped: run it next to the robots' router.

    A zenoh client of the robots' router watches every robot's command topic. When a robot's
    last command was a motion command and none came for --cmd-timeout s (the world's machine
    lost its link to the robots, or its world died with nothing left to stop them), the guard
    sends it zero twists, as twist_mux's topic timeout does; nothing while commands flow, so
    it never fights the world. One line per stop, and when the robot moves again.

    Exit codes: 0 --duration reached, 1 the router cannot be reached, 2 a bad robots file or
    option, 130/143 stopped by Ctrl-C/SIGTERM.

    Example (on the robots' machine): swarm robots guard --robots robots.toml --connect tcp/127.0.0.1:7447
    """
    # lazy: zenoh and the robots' protocol, which `swarm --help` must not pay
    from swarm.robots.config import load_robots
    from swarm.robots.guard import run_guard
    from swarm.robots.halt import HaltError, HaltPlan

    spec = load_robots(robots)
    plan = HaltPlan.from_robots(spec, connect or spec.guard.connect)
    try:
        code = run_guard(plan, cmd_timeout or spec.guard.cmd_timeout, lambda line: typer.echo(line), duration)
    except HaltError as e:
        raise fail(f"swarm robots guard: {e}", ExitCode.FAILED) from None
    raise typer.Exit(code)


def register(app: typer.Typer) -> None:
    app.add_typer(robots_app, name="robots")
