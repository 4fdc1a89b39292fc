"""The lab-scale rehearsal (issue 34, item 6; docs/guides/robots.md#rehearsal): scenarios/lab6.toml,
six TurtleBot3 Burgers whose paths cross in a 4 x 4 m arena.

In process (`swarm sim`, the whole run): without the filter (its table's `enabled = false`)
the start collides; with it, none, nothing leaves the arena, and the run converges. Against the
simulated fleet (`swarm up --robots` and `swarm robots sim` as processes, 30 ms latency, 0.01 m
pose noise, commands truncated to 0.01): the first 10 s of the run, where the paths cross
(`swarm sim`: the four collisions of the unfiltered run are in its first 6 s, its least
distance at 5.35 s; the filter acts from tick 0, and its least distance, 0.376 m, is reached
within 6 s too), filtered: no collision, no boundary exit, the filter at work, and every robot
got commands and was left stopped. benchmarks/rehearsal.py runs the whole
rehearsal, six and ten robots, with and without the filter.
"""

from __future__ import annotations

import re
import signal

import pytest
from deadlines import DEADLINE
from fleet_support import free_port
from runtime_helpers import SCENARIOS, start_up, swarm_cmd, wait_for

import swarm
from swarm.contracts.vocabulary import ExitCode

pytestmark = pytest.mark.slow

LAB6 = SCENARIOS / "lab6.toml"
ROBOTS = SCENARIOS / "robots" / "lab6.toml"


def with_safety(enabled: bool) -> str:
    text = LAB6.read_text()
    return text if enabled else text.replace("[safety]\n", "[safety]\nenabled = false\n", 1)


def test_lab6_collides_without_the_filter_and_not_with_it_under_sim(tmp_path, shipped_sim):
    figures = {}
    path = tmp_path / "lab6-False.toml"
    path.write_text(with_safety(False))
    summary = swarm.simulate(path).summary.to_dict()
    figures[False] = (summary["converged"], summary["safety"])
    # with the filter: scenarios/lab6.toml as shipped, its whole `swarm sim` run made once per
    # session (conftest.shipped_sim: the convergence checks of test_cli_offline read it too)
    res, out = shipped_sim("lab6")
    assert res.exit_code == ExitCode.OK, res.output[-3000:]
    summary = swarm.open_run(out).summary.to_dict()
    figures[True] = (summary["converged"], summary["safety"])
    converged, off = figures[False]
    assert converged and off["enabled"] is False and off["interventions"] == 0
    assert off["collisions"] > 0 and off["min_distance"] < 0.25, off  # the paths cross
    converged, on = figures[True]
    assert converged, on
    assert on["enabled"] is True and on["collisions"] == 0 and on["boundary_exits"] == 0, on
    assert on["interventions"] > 0 and on["min_distance"] >= 0.25, on


def test_lab6_on_the_fleet_keeps_its_robots_apart_and_in_the_arena(rt, tmp_path):
    duration, scale = 10.0, 2.0  # (was 40 s, then 20 s: the crossings are in the first 6 s)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    robots = tmp_path / "robots.toml"
    robots.write_text(re.sub(r'(?m)^connect\s*=\s*"[^"]*"', f'connect = "{endpoint}"', ROBOTS.read_text(), count=1))
    fleet = rt.tracker.spawn(
        swarm_cmd(
            *("robots", "sim", LAB6, "--robots", robots, "--latency", "0.03", "--pose-noise", "0.01"),
            *("--quantize", "0.01", "--time-scale", scale),
        ),
        "fleet",
    )
    wait_for(
        lambda: fleet.check_running("the fleet") or "fleet ready" in fleet.text(), DEADLINE, "the fleet to be ready"
    )
    up = start_up(rt.tracker, LAB6, tmp_path / "run", "--robots", robots, "--duration", duration, "--time-scale", scale)
    assert up.launcher.wait(DEADLINE + duration / scale) == ExitCode.OK, (
        up.launcher.text()[-3000:] + up.world_text()[-3000:]
    )
    fleet.popen.send_signal(signal.SIGINT)
    assert fleet.wait(DEADLINE) == ExitCode.INTERRUPTED, fleet.text()[-3000:]
    rt.tracker.assert_none_left()

    summary = up.summary()
    safety = summary["safety"]
    print(
        f"lab6 on the fleet, {duration:g} s: least distance {safety['min_distance']:.3f} m "
        f"(pair {safety['min_distance_pair']}), interventions {safety['interventions']}, "
        f"infeasible {safety['infeasible']}, saturations {safety['saturations']}"
    )
    assert safety["enabled"] is True and safety["radius"] == 0.25
    assert safety["collisions"] == 0 and safety["boundary_exits"] == 0, safety
    assert safety["interventions"] > 0, safety  # the paths crossed and the filter acted
    assert summary["ticks"] == round(duration / 0.05)
    # commands reached every robot, and every robot was left stopped by a zero twist
    report = fleet.text()
    for aid in range(1, 7):
        fig = summary["robots"]["agents"][str(aid)]
        assert fig["poses"] > 0 and fig["twists"] > 0, (aid, fig)
        m = re.search(rf"robot {aid}: (\d+) commands \(0 malformed\).*stopped by a zero twist", report)
        assert m and int(m[1]) > 0, report
