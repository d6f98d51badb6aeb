"""The clairvoyant ceiling (experiments.ceiling, sim.crowd_future): the people's walk without the drone is
the world's to the bit, the space-time search waits where it must and gives up where nothing opens, and
the command reports shares and refuses people who see the drone."""
import json

import numpy as np
import pytest

from conftest import BASE, make_scenario
from cli_in_process import run_main
from experiments.ceiling import CeilingConfig, clairvoyant_ceiling, earliest_arrival
from sim import World, load_scenario
from sim.controller import Reference
from sim.crowd_future import SeesDrone, blind_walk

NARROW = BASE.replace("width = 4.0", "width = 1.4")


def _walker(start, end, speed=1.0, delay=0.0):
    return (f'[[people]]\nbehaviour = "crossing"\nspeed = {speed}\nstart_delay = {delay}\n'
            f'waypoints = [{list(start)}, {list(end)}]\n')


def test_the_walk_without_the_drone_is_the_worlds_to_the_bit():
    sc = load_scenario("corridor4", 3)
    times, walk = blind_walk(sc, 3, 2.0)
    w = World(sc, seed=3, camera=False)
    for k in range(1, len(times)):
        w.step(Reference.hover([3.0, 0.5, 1.2]))  # the drone flies into the crowd: blind people ignore it
        assert w.time == times[k]
        np.testing.assert_array_equal(w.crowd.pos, walk[k])
    assert np.abs(walk[-1] - walk[0]).max() > 0.5  # they walked


def test_the_walk_is_refused_when_someone_sees_the_drone():
    sc = make_scenario(_walker((5.0, 1.0), (5.0, -1.0)) + "[crowd]\nsees_drone = true\n")
    with pytest.raises(SeesDrone, match=r"people \[0\] see the drone"):
        blind_walk(sc, 0, 1.0)


def _door(opens_at):
    """A 20 x 5 grid with a wall at x = 10 whose middle cell is free from step ``opens_at`` on."""
    def free(k):
        f = np.ones((20, 5), bool)
        f[10, :] = False
        f[10, 2] = k >= opens_at
        return f
    goal = np.zeros((20, 5), bool)
    goal[19, :] = True
    return free, goal


CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], bool)


def test_the_search_waits_for_a_door_and_gives_up_on_one_that_never_opens():
    free, goal = _door(0)
    assert earliest_arrival(free, (0, 2), goal, CROSS, 100) == 19  # one cell per step, straight through
    free, goal = _door(15)
    assert earliest_arrival(free, (0, 2), goal, CROSS, 100) == 25  # in the door once it is free at 15 and 16
    free, goal = _door(10**6)
    assert earliest_arrival(free, (0, 2), goal, CROSS, 100) is None  # the time runs out before the door opens
    free, goal = _door(15)
    assert earliest_arrival(free, (0, 2), goal, CROSS, 24) is None  # one step short
    free, goal = _door(0)
    blocked_start = lambda k: np.where(np.arange(20)[:, None] == 0, False, free(k))  # noqa: E731
    assert earliest_arrival(blocked_start, (0, 2), goal, CROSS, 100) is None


def test_an_empty_corridor_takes_its_length_at_top_speed():
    sc = make_scenario()
    fast = clairvoyant_ceiling(sc, 0, CeilingConfig(v_max=2.0))
    slow = clairvoyant_ceiling(sc, 0, CeilingConfig(v_max=1.0))
    assert fast.reachable and slow.reachable
    # 8 m from start to goal, less the goal's 0.4 m tolerance, on a 5 cm grid in 50 ms steps
    assert fast.time_to_goal == pytest.approx(7.6 / 2.0, abs=0.1)
    assert slow.time_to_goal == pytest.approx(7.6 / 1.0, abs=0.15)


def test_a_walker_ahead_delays_the_drone_and_one_that_stops_in_a_narrow_corridor_blocks_it():
    ahead = make_scenario(_walker((2.5, 0.0), (9.7, 0.0), speed=1.0), base=NARROW)
    r = clairvoyant_ceiling(ahead, 0)
    # no room to pass: the drone keeps 0.75 m behind a walker at 1 m/s who starts 2.5 m down the corridor, so
    # it is 8.6 m down (the goal's edge) when the walker is at 9.35 m, 6.85 s after the start
    assert r.reachable and r.time_to_goal == pytest.approx(6.85, abs=0.25)
    staying = make_scenario(_walker((8.0, 0.0), (5.0, 0.0), speed=1.0), base=NARROW)
    assert clairvoyant_ceiling(staying, 0) == clairvoyant_ceiling(staying, 0)  # deterministic
    assert not clairvoyant_ceiling(staying, 0).reachable  # it stops mid-corridor, facing the drone
    # in the 4 m corridor the same walker leaves room beside it, and a wider berth never arrives sooner
    wide = make_scenario(_walker((8.0, 0.0), (5.0, 0.0), speed=1.0))
    near, far = (clairvoyant_ceiling(wide, 0, CeilingConfig(clearance=c)) for c in (0.5, 1.2))
    assert near.reachable and far.reachable and far.time_to_goal >= near.time_to_goal


def test_a_gap_the_drone_fits_but_its_margin_does_not_is_a_way_only_without_the_margin():
    # a box leaves 1.0 m beside the wall: the drone's 0.87 m fits, 0.87 m plus 0.1 m on each side does not
    sc = make_scenario('[[obstacles]]\nkind = "box"\ncenter = [5.0, -0.5]\nsize = [0.4, 3.0, 2.0]\n')
    assert clairvoyant_ceiling(sc, 0).reachable
    assert not clairvoyant_ceiling(sc, 0, CeilingConfig(static_margin=0.1)).reachable
    with pytest.raises(ValueError, match="static_margin"):
        CeilingConfig(static_margin=-0.1)


def test_ceiling_command_prints_shares_and_writes_every_seed(tmp_path, capsys):
    f = tmp_path / "one.toml"
    f.write_text(BASE + _walker((8.0, 0.0), (2.0, 0.0), speed=1.0))
    out = tmp_path / "c.json"
    assert run_main(["ceiling", str(f), "--seeds", "2", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    assert "100.0" in text and "dev seeds 0-1" in text
    data = json.loads(out.read_text())
    assert [r["seed"] for r in data["scenarios"][str(f)]] == [0, 1]
    assert all(r["reachable"] and r["time_to_goal"] > 3.8 for r in data["scenarios"][str(f)])


def test_ceiling_command_refuses_people_who_see_the_drone(tmp_path, capsys):
    f = tmp_path / "aware.toml"
    f.write_text(BASE + _walker((8.0, 0.0), (2.0, 0.0)) + "[crowd]\nsees_drone = true\n")
    assert run_main(["ceiling", str(f), "--seeds", "1"]) == 2
    err = capsys.readouterr().err
    assert "see the drone" in err and "Traceback" not in err
