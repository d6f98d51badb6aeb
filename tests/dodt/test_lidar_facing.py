"""The LiDAR vote skips points whose surface could not have been seen back then (dodt.lidar.face_cos):
a static box the sensor passes shows a new face, whose points would otherwise vote moving."""
import numpy as np

from dodt.config import DODTConfig
from dodt.identification import faced_then, vote


def _face(x, rng, n=120):
    """Points on the plane x = ``x``, 0.4 m wide and 1.2 m tall, with 1 cm noise."""
    return np.column_stack([np.full(n, x) + rng.normal(0, 0.01, n), rng.uniform(-0.2, 0.2, n),
                            rng.uniform(0.3, 1.5, n)])


BEFORE, AFTER = np.array([0.0, 0.0, 1.0]), np.array([3.0, 0.0, 1.0])  # the sensor passes the box along x


def test_normals_face_the_sensor_now_and_tell_which_faces_faced_it_then():
    rng = np.random.default_rng(0)
    back = _face(1.4, rng)  # the box's face towards +x: seen from AFTER only
    assert faced_then(back, AFTER, [AFTER], -0.1).all()
    assert not faced_then(back, AFTER, [BEFORE], -0.1).any()
    assert faced_then(back, AFTER, [BEFORE, AFTER], -0.1).all()  # faced one of the scans
    assert faced_then(back, AFTER, [BEFORE], None) is None  # off
    assert faced_then(back[:2], AFTER, [BEFORE], -0.1) is None  # too few points for normals


def test_a_new_face_of_a_passed_box_does_not_vote_and_a_walker_still_does():
    rng = np.random.default_rng(1)
    cfg = DODTConfig()
    ident, lc = cfg.identification, cfg.lidar
    front, back = _face(1.0, rng), _face(1.4, rng)  # the box, 0.4 m deep
    dt, v_box = 0.5, np.array([0.8, 0.0, 0.0])  # its box slid 0.4 m as the back face came into view
    votes, valid, _ = vote(back, front, dt, v_box, None, None, 0.0, ident)
    assert valid == len(back) and votes / valid >= ident.vote_ratio  # without the test: moving
    seen = faced_then(back, AFTER, [BEFORE], lc.face_cos)
    votes, valid, skipped = vote(back, front, dt, v_box, None, None, 0.0, ident, seen_then=seen)
    assert valid == 0 and skipped == len(back)
    # a walker's face towards the sensor, 0.4 m nearer the sensor than half a second before, faced it
    # then too: its points vote as before
    walker_then, walker_now = _face(2.4, rng), _face(2.0, rng)
    seen = faced_then(walker_now, BEFORE, [BEFORE], lc.face_cos)
    assert seen.all()
    votes, valid, _ = vote(walker_now, walker_then, dt, np.array([-0.8, 0.0, 0.0]), None, None, 0.0, ident,
                           seen_then=seen)
    assert valid == len(walker_now) and votes / valid >= ident.vote_ratio
