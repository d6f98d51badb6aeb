"""A coasting track the LiDAR's rays pass through is dropped (dodt.tracker.Tracker.drop_seen_through_lidar):
the scan sees past its predicted place, so nothing is there; occluded or still there, it coasts on."""
import math

import numpy as np
import pytest

from dodt.config import DODTConfig
from dodt.frames import LidarScan
from tests.dodt.test_association import FPS, Feed

SENSOR = np.array([0.0, 0.0, 1.3])


def scan_of(surface_range, yaw: float = 0.0) -> LidarScan:
    """A scan from SENSOR turned by ``yaw``, rays every degree in azimuth (sensor frame) and elevation (-7 to
    52 deg), each returning at ``surface_range(world azimuth, elevation)`` (horizontal metres; None: no return)."""
    az, el = np.meshgrid(np.radians(np.arange(-180.0, 180.0)), np.radians(np.arange(-7.0, 53.0)))
    az, el = az.ravel(), el.ravel()
    reach = np.array([surface_range(a + yaw, e) for a, e in zip(az, el)], dtype=object)
    hit = np.array([r is not None for r in reach])
    az, el, reach = az[hit], el[hit], reach[hit].astype(float)
    ranges = reach / np.cos(el)
    pts = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)]) * ranges[:, None]
    T = np.eye(4)
    T[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
    T[:3, 3] = SENSOR
    return LidarScan(points=pts.astype(np.float32), ranges=ranges.astype(np.float32), azimuth=az.astype(np.float32),
                     elevation=el.astype(np.float32), stamp=0.0, T_world_sensor=T, n_rays=len(hit))


BEHIND = -3.0  # the person stood at x = -3 m, behind the sensor: only the LiDAR sees there


def wall(a, e):
    """A wall 6 m away all round."""
    return 6.0


def occluder(a, e):
    """The wall, and a pillar 1.5 m off the sensor between it and the person's place."""
    return 1.5 if abs(math.remainder(a - math.pi, 2 * math.pi)) < math.radians(15) else 6.0


def there(a, e):
    """The wall, and the person where the track predicts (3 m away, up to 1.8 m tall)."""
    near = abs(math.remainder(a - math.pi, 2 * math.pi)) < math.radians(4) and 3.0 * math.tan(e) + 1.3 <= 1.8
    return 3.0 if near else 6.0


@pytest.mark.parametrize("surface, yaw, dropped", [
    (wall, 0.0, True),  # the rays through its place end on the wall behind: not there
    (wall, 2.0, True),  # the same from a turned sensor
    (occluder, 0.0, False),  # something nearer covers its place: it may be behind it
    (occluder, 2.0, False),  # the same from a turned sensor (its rays read in the sensor's frame)
    (there, 0.0, False),  # returns where it should be
    (there, -1.0, False),
    (lambda a, e: None, 0.0, False),  # no returns: nothing to tell
])
def test_a_coasting_track_the_scan_sees_through_is_dropped(surface, yaw, dropped):
    cfg = DODTConfig()
    feed = Feed(cfg)
    for k in range(5):  # a person standing behind the sensor, measured
        feed(k / FPS, [np.array([BEHIND, 0.0, 0.9])])
    assert len(feed.tracker.tracks) == 1
    scan = scan_of(surface, yaw)
    n = feed.tracker.clock.intervals(cfg.track.seen_through_after)  # 7 missed frames at 30 Hz
    assert n == 7
    for k in range(5, 5 + n - 1):  # missed, not yet long enough
        feed(k / FPS, [])
        assert feed.tracker.drop_seen_through_lidar(scan) == 0
    feed((5 + n - 1) / FPS, [])
    assert feed.tracker.drop_seen_through_lidar(scan) == int(dropped)
    assert (feed.tracker.tracks == []) == dropped
