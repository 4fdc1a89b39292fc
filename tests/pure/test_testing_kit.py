"""swarm.testing, the kit a law author tests a law with (docs/guides/writing-a-law.md#unit-testing):
the guide's blocks run as written (and fail for a law that turns the wrong way); FrameBuilder's
observations are the ones the agent's brain builds; FakeWorldLink runs the brain as `swarm sim`
does (the same commands and the same track as the engine, to the bit); bad input names the
argument; the kit imports no zenoh."""

from __future__ import annotations

import math
import re
import sys
import types
from pathlib import Path

import pytest
from test_layers import MODULES, imports_of, module_of_file, project_files

from swarm.agents.brain import AgentBrain
from swarm.contracts import wire
from swarm.contracts.frames import Contact, SensorFrame
from swarm.contracts.observation import Search
from swarm.contracts.scenario import parse_scenario
from swarm.offline.sim import run_sim
from swarm.testing import FakeWorldLink, FrameBuilder, Neighbour

ROOT = Path(__file__).resolve().parents[2]
GUIDE = ROOT / "docs" / "guides" / "writing-a-law.md"


# -- the guide's blocks, as written ------------------------------------------------------------------


def guide_block(first_line: str) -> str:
    """The guide's ```python block whose first line starts with `first_line`."""
    blocks = re.findall(r"```python\n(.*?)```", GUIDE.read_text(), re.S)
    found = [b for b in blocks if b.startswith(first_line)]
    assert len(found) == 1, f"{GUIDE}: {len(found)} python blocks start with {first_line!r}"
    return found[0]


def run_guide_tests(tmp_path: Path, monkeypatch: pytest.MonkeyPatch, mylaws: str) -> list[str]:
    """Write `mylaws` as mylaws.py, load the guide's test_mylaws.py block as a module and run
    each of its test functions; returns their names."""
    (tmp_path / "mylaws.py").write_text(mylaws)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.delitem(sys.modules, "mylaws", raising=False)
    module = types.ModuleType("test_mylaws")
    exec(compile(guide_block("# test_mylaws.py"), f"{GUIDE}:test_mylaws", "exec"), module.__dict__)
    names = sorted(n for n in vars(module) if n.startswith("test_"))
    for name in names:
        getattr(module, name)()
    monkeypatch.delitem(sys.modules, "mylaws", raising=False)
    return names


def guide_laws() -> str:
    return guide_block("# mylaws.py, next to the scenario file") + "\n" + guide_block("# mylaws.py, continued")


def test_the_guides_law_tests_run_as_written(tmp_path, monkeypatch):
    names = run_guide_tests(tmp_path, monkeypatch, guide_laws())
    assert names == [
        "test_pursuit_turns_towards_its_out_neighbour",
        "test_ring_brings_the_leader_onto_its_orbit",
        "test_the_commands_it_sends",
    ]


@pytest.mark.parametrize(
    "wrong, right",
    [
        (
            'return obs.params["k"] * math.sin(obs.out.bearing - obs.heading)',
            'return -obs.params["k"] * math.sin(obs.out.bearing - obs.heading)',
        ),
        ("want = lam - obs.direction", "want = lam + obs.direction"),
    ],
    ids=["pursuit-away", "ring-outwards"],
)
def test_the_guides_tests_fail_for_a_law_that_turns_the_wrong_way(tmp_path, monkeypatch, wrong, right):
    laws = guide_laws()
    assert wrong in laws
    with pytest.raises(AssertionError):
        run_guide_tests(tmp_path, monkeypatch, laws.replace(wrong, right))


# -- FrameBuilder ---------------------------------------------------------------------------------------


def echo(obs):
    return 0.0


def test_an_observation_is_the_one_the_brain_builds():
    b = FrameBuilder(id=4, speed=2.0, dt=0.05, c1=0.3, c2=0.2, params={"k": 2.0}, max_turn_rate=1.5)
    neighbours = [Neighbour(2, x=3.0, y=4.0, heading=0.3, hops=0), Neighbour(7, bearing=-1.0, range=2.5)]
    frame = b.frame(x=1.0, y=1.0, heading=0.25, neighbours=neighbours, tick=9)
    assert frame == SensorFrame(
        9,
        9 * 0.05,
        4,
        0.25,
        (Contact(2, math.atan2(3.0, 2.0), 0.3, math.hypot(2.0, 3.0), 0), Contact(7, -1.0, 0.0, 2.5, -1)),
    )
    brain = AgentBrain(b.conf(n_agents=3))
    brain.last_u = 0.125
    state: dict = {}
    brain.state = state
    got = brain._observe(frame, frame.contacts[0], None)
    built = b.observation(x=1.0, y=1.0, heading=0.25, neighbours=neighbours, out=2, tick=9, last_u=0.125, state=state)
    assert built == got and built.params == {"k": 2.0}


def test_a_leaders_target_is_relative_and_followers_never_get_one():
    b = FrameBuilder(role="leader", orbit_radius=5.0, direction="cw")
    obs = b.observation(x=2.0, y=-1.0, target=(5.0, 3.0))
    assert obs.target == (3.0, 4.0) and obs.target_range == 5.0 and obs.direction == -1 and obs.out is None
    with pytest.raises(ValueError, match=r"observation: target: a leader needs"):
        b.observation()
    with pytest.raises(ValueError, match=r"frame: target: followers never know the target"):
        FrameBuilder().frame(target=(0.0, 0.0))


def test_range_and_field_of_view_hide_neighbours_as_the_worlds_sensors_do():
    b = FrameBuilder(sense_range=10.0, fov=math.pi / 2)  # +-45 degrees about the heading
    near_ahead = Neighbour(2, bearing=0.5, range=10.0)  # on the edge of the range: sensed
    far = Neighbour(3, bearing=0.0, range=10.5)
    behind = Neighbour(4, x=-1.0, y=0.0)
    assert [c.id for c in b.contacts(neighbours=[near_ahead, far, behind])] == [2]
    with pytest.raises(ValueError, match=r"observation: out: 3 is not a neighbour the agent senses \(sensed: 2\)"):
        b.observation(neighbours=[near_ahead, far], out=3)


@pytest.mark.parametrize(
    "make, error, message",
    [
        (
            lambda: FrameBuilder(role="boss"),
            ValueError,
            "FrameBuilder: role: expected one of ('follower', 'leader'), got 'boss'",
        ),
        (lambda: FrameBuilder(speed=0.0), ValueError, "FrameBuilder: speed: expected a positive number"),
        (lambda: FrameBuilder(dt="0.1"), TypeError, "FrameBuilder: dt: expected a number, got '0.1'"),
        (lambda: FrameBuilder(c1=math.nan), ValueError, "FrameBuilder: c1: expected a finite number"),
        (lambda: FrameBuilder(role="leader"), ValueError, "FrameBuilder: orbit_radius: a leader needs one"),
        (lambda: FrameBuilder(direction="left"), ValueError, "FrameBuilder: direction: expected one of"),
        (lambda: FrameBuilder(selection="fixed"), ValueError, 'FrameBuilder: follow: selection "fixed" needs'),
        (lambda: FrameBuilder(params={"k": True}), TypeError, "FrameBuilder: params['k']: expected a number"),
        (lambda: FrameBuilder(hysteresis=1.0), ValueError, "FrameBuilder: hysteresis: expected a fraction"),
        (lambda: FrameBuilder(fov=7.0), ValueError, "FrameBuilder: fov: expected at most 2 pi"),
        (lambda: Neighbour(3, x=1.0), ValueError, "Neighbour(3): y: missing"),
        (lambda: Neighbour(3, bearing=1.0), ValueError, "Neighbour(3): range: missing"),
        (lambda: Neighbour(3, x=1.0, y=1.0, range=2.0), ValueError, "Neighbour(3): give x and y"),
        (lambda: Neighbour(3, bearing=1.0, range=-2.0), ValueError, "Neighbour(3): range: expected a distance"),
        (lambda: Neighbour(-1, x=0.0, y=0.0), ValueError, "Neighbour(-1): id: expected an integer >= 0"),
        (lambda: Neighbour(3, x=0.0, y=0.0, hops=-2), ValueError, "Neighbour(3): hops: expected an integer >= -1"),
        (lambda: FrameBuilder().observation(heading=math.inf), ValueError, "observation: heading: expected a finite"),
        (
            lambda: FrameBuilder().observation(neighbours=[(2, 0.0, 0.0)]),
            TypeError,
            "observation: neighbours: expected Neighbour",
        ),
        (
            lambda: FrameBuilder().observation(neighbours=[Neighbour(1, x=0.0, y=1.0)]),
            ValueError,
            "neighbours: 1 is the agent's own id",
        ),
        (
            lambda: FrameBuilder().observation(neighbours=[Neighbour(2, x=0.0, y=1.0), Neighbour(2, x=1.0, y=0.0)]),
            ValueError,
            "neighbours: id 2 given twice",
        ),
        (
            lambda: FrameBuilder().observation(out=2),
            ValueError,
            "observation: out: 2 is not a neighbour the agent senses (sensed: none)",
        ),
        (lambda: FrameBuilder().observation(tick=-1), ValueError, "observation: tick: expected an integer >= 0"),
        (lambda: FrameBuilder().observation(state=[]), TypeError, "observation: state: expected a dict"),
        (
            lambda: FrameBuilder(role="leader", orbit_radius=1.0).observation(target=(0.0,)),
            TypeError,
            "observation: target: expected a pair of numbers",
        ),
        (
            lambda: FrameBuilder().observation(
                neighbours=[Neighbour(2, x=1.0, y=0.0)], out=2, search=Search(0.0, 0.0, 1.0, 1)
            ),
            ValueError,
            "observation: search: only a follower with nobody to follow",
        ),
        (
            lambda: FakeWorldLink(echo, FrameBuilder(role="leader", orbit_radius=2.0)),
            ValueError,
            "frame: target: a leader needs",
        ),
        (lambda: FakeWorldLink(lambda a, b: 0.0), TypeError, "FakeWorldLink: law: <function"),
        (lambda: FakeWorldLink(3), TypeError, "FakeWorldLink: law: expected a function"),
        (lambda: FakeWorldLink(echo, x=math.nan), ValueError, "FakeWorldLink: x: expected a finite number"),
        (lambda: FakeWorldLink("no_such_module_xyz:law"), ValueError, "cannot import module 'no_such_module_xyz'"),
        (lambda: FakeWorldLink(echo).run(-1), ValueError, "run: ticks: expected an integer >= 0"),
    ],
)
def test_bad_input_is_refused_naming_the_argument(make, error, message):
    with pytest.raises(error) as exc:
        make()
    assert message in str(exc.value), str(exc.value)


# -- FakeWorldLink -----------------------------------------------------------------------------------


def test_a_fake_link_gives_the_commands_and_the_track_of_swarm_sim(base):
    """The scenario of conftest's `base` (leader 1, followers 2 -> 1 and 3 -> 2, selection
    fixed): agent 2's brain in a FakeWorldLink whose neighbours follow their `swarm sim`
    tracks tick by tick sends the commands it sent in the engine, and moves as it moved."""
    s = parse_scenario(base)
    a = run_sim(s, duration=1.0).recorder.arrays()
    ids = [int(i) for i in a["ids"]]
    k = ids.index(2)
    spec = s.agent(2)
    agent = FrameBuilder(
        id=2,
        speed=spec.speed,
        dt=s.run.dt,
        c1=s.gains.c1,
        c2=s.gains.c2,
        selection=s.sensing.selection,
        follow=spec.follow,
    )
    link = FakeWorldLink("bearing", agent, x=spec.x, y=spec.y, heading=spec.heading, n_agents=len(ids))
    ticks = len(a["u"]) - 1
    for t in range(ticks):
        for j, i in enumerate(ids):
            if i != 2:  # the others where the engine had them at this tick
                link.move(Neighbour(i, x=float(a["x"][t, j]), y=float(a["y"][t, j]), heading=float(a["heading"][t, j])))
        assert link.pose == (a["x"][t, k], a["y"][t, k], a["heading"][t, k])
        assert link.tick().u == a["u"][t, k]
    assert ticks > 10 and [c.out for c in link.commands] == [1] * ticks


def test_a_fake_link_records_frames_observations_commands_and_the_track():
    link = FakeWorldLink(
        echo,
        FrameBuilder(dt=0.5, speed=2.0),
        heading=math.pi / 2,
        neighbours=[Neighbour(5, bearing=0.0, range=4.0, speed=1.0)],
    )
    assert link.neighbours[5].x == 4.0 and link.neighbours[5].y == 0.0  # placed as seen from the start
    sent = link.run(2)
    assert [f.tick for f in link.frames] == [0, 1] and [o.time for o in link.observations] == [0.0, 0.5]
    assert link.commands == sent and all(isinstance(c, wire.Command) for c in sent)
    assert link.track[0] == (0.0, 0.0, math.pi / 2) and link.track[1][1] == pytest.approx(1.0)  # 2 m/s north
    assert link.neighbours[5].x == pytest.approx(5.0)  # it moved 1 m/s east for two ticks
    link.remove(5)
    assert link.tick().out is None and link.observations[-1].contacts == ()
    with pytest.raises(KeyError, match="no neighbour 5"):
        link.remove(5)


def test_a_fake_link_runs_the_brain_saturation_nan_and_the_laws_state():
    def law(obs):
        obs.state["calls"] = obs.state.get("calls", 0) + 1
        return math.nan if obs.tick == 1 else 10.0

    link = FakeWorldLink(law, FrameBuilder(max_turn_rate=0.4))
    assert [c.u for c in link.run(3)] == [0.4, 0.4, 0.4]  # saturated; the NaN held the last u
    assert link.state == {"calls": 3} and link.brain.nonfinite == 1


def test_a_named_leader_law_runs_in_a_fake_link():
    link = FakeWorldLink("cc", FrameBuilder(role="leader", orbit_radius=5.0, dt=0.1), x=-20.0, target=(0.0, 0.0))
    phases = [c.phase for c in link.run(400)]
    assert phases[0] == "arc1" and phases[-1] == "orbit" and abs(link.target_range - 5.0) < 1e-3


# -- layers --------------------------------------------------------------------------------------------


@pytest.mark.slow
def test_the_kit_imports_no_zenoh():
    """Statically: importing swarm.testing and running it loads no module that imports zenoh
    (the modules its files import, theirs at module level, and every parent package's)."""
    files = {module_of_file(p): p for p in project_files()}
    seen: set[str] = set()
    todo = [m for m in files if m.startswith("swarm.testing")]
    zenoh = []
    while todo:
        here = todo.pop()
        if here in seen:
            continue
        seen.add(here)
        todo += [here.rpartition(".")[0]] if "." in here else []  # its package's __init__ runs first
        for _, mod, inside in imports_of(files[here]):
            if inside and not here.startswith("swarm.testing"):
                continue  # lazy: runs only if called
            if mod.split(".")[0] == "zenoh":
                zenoh.append(here)
            while mod and mod not in MODULES:  # `from swarm.x import name`: the module swarm.x
                mod = mod.rpartition(".")[0]
            if mod:
                todo.append(mod)
    assert {"swarm.testing.link", "swarm.agents.brain", "swarm.world.kinematics", "swarm.contracts.wire"} <= seen
    assert "swarm.world.inbox" not in seen and not zenoh, zenoh
