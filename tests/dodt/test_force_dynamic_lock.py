"""The force-dynamic lock (dodt.identification.decide) counts the frames that carried evidence: a
coasting track's held label does not lock it, and a LiDAR track's window is counted in its scans."""
import numpy as np

from dodt.config import DODTConfig, IdentificationConfig
from dodt.identification import decide
from dodt.windows import FrameClock
from tests.dodt.test_identification import K, T_CAM, frames_of, measure_slab, slab


def _clock(rate: float) -> FrameClock:
    clock = FrameClock()
    for _ in range(3):
        clock.observe(1.0 / rate)
    return clock


def test_the_lock_window_is_counted_at_the_measuring_sensors_period():
    """At 10 Hz scans the window of 29/30 s holds 11 labels, a third of them dynamic locks; counted at the
    camera's 30 Hz the window holds 30 labels, which 11 scans' worth of camera frames do not fill. A track
    both sensors measured counts each label for its sensor's period: 15 camera frames dynamic (0.5 s)
    and 6 static scans (0.6 s) fill the LiDAR's 1.1 s window, a third of it dynamic."""
    cfg = IdentificationConfig()
    cam, scans = _clock(30.0), _clock(10.0)
    w = frames_of(cfg.force_dynamic_span, 10.0)
    assert w == 11
    cand = [False] * 5  # nothing moving now: only the lock can keep it dynamic

    def by_scans(labels):
        return [(x, scans.period) for x in labels]

    locked = [False] * (w - 4) + [True] * 4
    assert decide(cand, by_scans(locked), cfg, cam, scans)
    assert not decide(cand, by_scans([False] * (w - 3) + [True] * 3), cfg, cam, scans)
    assert not decide(cand, by_scans(locked)[:-1], cfg, cam, scans)  # 1.0 s: the window is not filled
    assert not decide(cand, [(x, cam.period) for x in locked], cfg, cam)  # at the camera's period: 30 labels
    mixed = [(True, cam.period)] * 15 + [(False, scans.period)] * 6
    assert decide(cand, mixed, cfg, cam, scans)
    # the window filled, 10 camera frames (0.33 s) dynamic in it: under a third
    assert not decide(cand, [(False, cam.period)] * 15 + [(True, cam.period)] * 10 + [(False, scans.period)] * 7,
                      cfg, cam, scans)
    assert decide(cand, [(False, cam.period)] * 15 + [(True, cam.period)] * 11 + [(False, scans.period)] * 7,
                  cfg, cam, scans)


def test_frames_coasted_through_do_not_lock_a_track_dynamic():
    """A slab standing for half a second walks off at 1 m/s and is labelled dynamic, is missed for 12
    frames (coasting, its label held), then stands still: three measured frames that are no candidates
    release it. Counted, the held labels would have made over 10 of the last 30 frames dynamic and
    locked it for good."""
    cfg = DODTConfig()
    dt = 1 / 30
    clouds, track, labels = {}, None, []

    def measure(k, pts, velocity):
        nonlocal track
        track = measure_slab(cfg, track, clouds, k, pts, velocity)
        labels.append(track.geometric_dynamic)

    for k in range(15):  # standing
        measure(k, slab(3.0, 0.0, n=300, seed=k, width=0.15), [0.0, 0.0])
    for k in range(15, 25):  # walking sideways
        measure(k, slab(3.0, (k - 14) / 30, n=300, seed=k, width=0.15), [0.0, 1.0])
    assert not any(labels[:15]) and labels[-1] and sum(labels) < 10
    for k in range(25, 37):  # missed: the track coasts, its label held
        track.kf.predict(dt)
        track.coasting = True
        track.identify(k, {j: T_CAM for j in clouds}, clouds.get, K, 5.0)
        assert track.geometric_dynamic
    for k in range(37, 41):  # seen again, standing
        measure(k, slab(3.0, 0.4, n=300, seed=k, width=0.15), [0.0, 0.0])
    r = frames_of(cfg.identification.release_span)
    assert all(labels[25:25 + r - 1]) and not any(labels[25 + r - 1:])


def _lidar_track(cfg, height):
    from dodt.detection import Detection
    from dodt.tracker import Track

    det = Detection.from_bounds(np.array([3.0, 0.0, 1.7 - height]), np.array([3.4, 0.4, 1.7]), "lidar")
    return Track(1, det, 0, 0.0, cfg)


def test_the_lock_holds_a_lidar_track_only_while_its_box_is_person_tall():
    """A track the LiDAR measures, locked dynamic by its history, and no candidate now: with a
    person-tall box (a person's LiDAR box reaches the floor) the lock keeps it dynamic; with a box
    shorter than motion.height's lower bound (a fragment of a shelf the track was carried onto) it does
    not. A camera track keeps the lock whatever its height (the image's edge cuts people's boxes)."""
    cfg = DODTConfig()
    scans = _clock(10.0)
    w = frames_of(cfg.identification.force_dynamic_span, 10.0)
    for height, by_lidar, held in [(1.7, True, True), (0.6, True, False), (0.6, False, True)]:
        track = _lidar_track(cfg, height)
        track.dynamic_history.extend([(True, 1)] * w)
        track._decide(False, scans, by_lidar=by_lidar)
        assert track.geometric_dynamic == held, (height, by_lidar)
