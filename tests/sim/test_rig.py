"""Sensor rigs (sim.rig) and the cameras beyond the first (sim.extra_cameras)."""
import numpy as np
import pytest

from conftest import make_scenario
from experiments.config_limits import RIG_NAMES
from experiments.episode import EpisodeConfig, run_episode
from experiments.episode_log import read_log
from sim import World, load_scenario
from sim.rig import RIGS, SensorMount, cameras, lidars, rig, rig_of
from sim.scenario import ScenarioError


def test_the_named_rigs_are_those_the_configuration_accepts():
    assert tuple(RIGS) == RIG_NAMES
    assert [m.yaw for m in cameras(rig("surround4"))] == [0.0, 90.0, 180.0, -90.0]
    assert len(lidars(rig("lidar"))) == 1 and len(cameras(rig("lidar"))) == 1
    assert cameras(rig("front"))[0].yaw == 0.0


def test_bad_rigs_and_mounts_are_named():
    with pytest.raises(ValueError, match="unknown rig 'sides'.*front, front_back"):
        rig("sides")
    with pytest.raises(ValueError, match="kind must be"):
        SensorMount("radar", "r")
    with pytest.raises(ValueError, match="yaw must be"):
        SensorMount("camera", "c", float("nan"))


def frames(world, n):
    out = []
    for _ in range(n):
        f = world.step()
        if f is not None:
            out.append((f, world.latest_extra_frames()))
    return out


@pytest.fixture(scope="module")
def two_worlds():
    sc = load_scenario("crossing")
    plain = World(sc, seed=3, render_process=False, renderer="gl")
    rigged = World(sc, seed=3, render_process=False, renderer="gl")
    rigged.add_cameras([180.0, 90.0])
    yield frames(plain, 24), frames(rigged, 24)
    plain.close()
    rigged.close()


def test_other_cameras_change_nothing_of_the_first_cameras_frames(two_worlds):
    plain, rigged = two_worlds
    assert len(plain) == len(rigged) > 3
    for (a, extra_a), (b, _) in zip(plain, rigged):
        assert extra_a == ()
        assert np.array_equal(a.depth, b.depth) and np.array_equal(a.T_world_camera, b.T_world_camera)


def test_each_other_camera_looks_its_way_from_the_same_instant(two_worlds):
    _, rigged = two_worlds
    first, extra = rigged[-1]
    assert len(extra) == 2
    back, left = extra
    for f in extra:
        assert f.stamp == first.stamp and f.seq == first.seq and f.color is None
        assert f.depth.dtype == np.uint16 and f.depth.shape == first.depth.shape
        assert np.count_nonzero(f.depth) > 0.2 * f.depth.size  # it sees the corridor
    # optical axes: back is the first's reversed, left the first's turned +90 deg about z
    z0, zb, zl = first.T_world_camera[:3, 2], back.T_world_camera[:3, 2], left.T_world_camera[:3, 2]
    assert np.allclose(zb, -z0, atol=1e-9)
    assert np.allclose(zl, [-z0[1], z0[0], z0[2]], atol=1e-9)
    assert not np.array_equal(back.depth, first.depth)


SENSORS = """
[[sensors]]
kind = "camera"
name = "front"

[[sensors]]
kind = "camera"
name = "back"
yaw_deg = 180

[[sensors]]
kind = "lidar"
name = "top"
points_per_scan = 5000
elevation_min_deg = -15
"""


def test_a_scenario_declares_its_rig_and_rig_of_prefers_the_command_line():
    sc = make_scenario(SENSORS)
    front, back, top = sc.sensors
    assert (front.kind, back.yaw, top.kind) == ("camera", 180.0, "lidar")
    model = top.lidar_model()
    assert model.points_per_scan == 5000 and model.elevation_min == pytest.approx(np.radians(-15))
    assert rig_of(None, sc) == ("scenario", sc.sensors)
    assert rig_of("lidar", sc) == ("lidar", RIGS["lidar"])
    assert rig_of(None, make_scenario()) == ("front", RIGS["front"])


def test_a_lidar_under_the_body_hangs_upside_down():
    """Under the body a Mid-360 hangs upside down: its field, in the body's frame, is -52 to +7 deg, unless
    the file says otherwise; the named rig lidar_below carries it."""
    sc = make_scenario('[[sensors]]\nkind = "camera"\n[[sensors]]\nkind = "lidar"\nmount = "below"\n'
                       '[[sensors]]\nkind = "lidar"\nname = "low"\nmount = "below"\nelevation_max_deg = 2\n')
    _, below, low = sc.sensors
    for m in (below, lidars(rig("lidar_below"))[0]):
        model = m.lidar_model()
        assert m.mount == "below" and m.T_body_lidar()[2, 3] == pytest.approx(-0.12)
        assert (np.degrees(model.elevation_min), np.degrees(model.elevation_max)) == pytest.approx((-52.0, 7.0))
    assert np.degrees(low.lidar_model().elevation_max) == pytest.approx(2.0)
    assert np.degrees(low.lidar_model().elevation_min) == pytest.approx(-52.0)
    top = lidars(rig("lidar"))[0]
    assert top.T_body_lidar()[2, 3] == pytest.approx(0.12) and np.degrees(top.lidar_model().elevation_min) == \
        pytest.approx(-7.0)
    with pytest.raises(ValueError, match="mount must be"):
        SensorMount("lidar", "l", mount="under")


@pytest.mark.parametrize("bad, message", [
    ('[[sensors]]\nkind = "lidar"\n', "the first sensor is the \\[camera\\] table's"),
    ('[[sensors]]\nkind = "camera"\nyaw_deg = 90\n', "the first sensor is the \\[camera\\] table's"),
    ('[[sensors]]\nkind = "radar"\n', "sensors\\[0\\].kind"),
    ('[[sensors]]\nkind = "camera"\nname = "a"\n[[sensors]]\nkind = "camera"\nname = "a"\n', "unique"),
    ('[[sensors]]\nkind = "camera"\n[[sensors]]\nkind = "lidar"\nelevation_max_deg = -20\n', "must exceed"),
    ('[[sensors]]\nkind = "camera"\n[[sensors]]\nkind = "lidar"\nwavelength = 905\n', "wavelength"),
    ('[[sensors]]\nkind = "camera"\n[[sensors]]\nkind = "lidar"\nmount = "side"\n', "mount.*top, below"),
])
def test_a_bad_rig_in_a_scenario_is_one_clear_error(bad, message):
    with pytest.raises(ScenarioError, match=message):
        make_scenario(bad)


def test_an_episode_flies_the_scenarios_rig(tmp_path):
    s = run_episode(make_scenario(SENSORS), seed=1, perception="oracle", out=tmp_path,
                    cfg=EpisodeConfig(duration=0.5, static_map="truth"))
    assert s["rig"] == "scenario"
    header = read_log(tmp_path / "log.jsonl.gz")[0]
    assert [(x["name"], x["kind"], x["yaw"]) for x in header["sensors"]] == \
        [("front", "rgbd", 0.0), ("back", "rgbd", 180.0), ("top", "lidar", 0.0)]
