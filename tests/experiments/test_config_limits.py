"""experiments.config_limits: a type and a range for every configuration key, and their check."""
import dataclasses
import math
import re
import typing

import pytest
from hypothesis import given, settings, strategies as st

from dodt.presets import PRESETS
from experiments.config import parse_value
from experiments.registry import builtin_sections
from experiments.config_limits import LIMITS, Limit, check_config, check_value


def _defaults() -> dict:
    """Each section's default configuration: the dataclass' defaults; dodt's from its preset."""
    return builtin_sections()


def _leaves(obj, prefix: str):
    """(dotted key, value, type hint) of every leaf field of a dataclass, nested ones walked into."""
    hints = typing.get_type_hints(type(obj))
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            yield from _leaves(v, f"{prefix}{f.name}.")
        else:
            yield f"{prefix}{f.name}", v, hints[f.name]


DEFAULT_LEAVES = {k: (v, h) for s, cfg in _defaults().items() for k, v, h in _leaves(cfg, s + ".")}


# ------------------------------------------------------------------------------------------ (a) coverage

def test_every_leaf_key_has_a_limit_and_every_limit_a_field():
    assert sorted(set(DEFAULT_LEAVES) - set(LIMITS)) == []
    assert sorted(set(LIMITS) - set(DEFAULT_LEAVES)) == []


@pytest.mark.parametrize("key", sorted(DEFAULT_LEAVES))
def test_each_limit_has_its_fields_type(key):
    lim, hint = LIMITS[key], DEFAULT_LEAVES[key][1]
    args = typing.get_args(hint)
    optional = type(None) in args
    assert lim.optional == optional, key
    if optional:
        hint = next(a for a in args if a is not type(None))
        args = typing.get_args(hint)
    if typing.get_origin(hint) is tuple:
        assert lim.length is not None, key
        if args and args[-1] is not Ellipsis:
            assert lim.length == (len(args), len(args)), key
        hint = args[0]
    else:
        assert lim.length is None, key
    expected = {bool: ("bool", False), int: ("number", True), float: ("number", False), str: ("string", False)}
    assert (lim.kind, lim.integer) == expected[hint], key


def test_string_choices_are_the_codes_own():
    from dodt.learned import views, yolo
    from experiments.commands.common import MAX_FRAME_LATENCY, SEED_MAX
    from experiments.episode_config import STATIC_MAPS
    from sim.scenario import RENDERER_CHOICES

    assert LIMITS["episode.renderer"].choices == RENDERER_CHOICES
    assert LIMITS["episode.static_map"].choices == STATIC_MAPS
    assert LIMITS["dodt.learned.layout"].choices == ("auto",) + yolo.LAYOUTS
    assert LIMITS["dodt.learned.views"].choices == tuple(views.VIEWS)
    assert {ch for ch, _, _ in yolo.PREPROCESS.values()} <= set(LIMITS["dodt.learned.channels"].choices)
    assert {box for _, _, box in yolo.PREPROCESS.values()} <= set(LIMITS["dodt.learned.letterbox"].choices)
    assert {scale for _, scale, _ in yolo.PREPROCESS.values()} == {1.0, 1.0 / 255.0}
    assert LIMITS["episode.frame_latency"].hi == MAX_FRAME_LATENCY
    assert LIMITS["oracle.noise_seed"].hi == SEED_MAX


# ------------------------------------------------------------------------------------------ (b) what is used

@pytest.mark.parametrize("name", sorted(PRESETS))
def test_every_preset_passes(name):
    check_config("dodt", PRESETS[name])


def test_every_default_passes():
    from experiments.perception_modes import NOISY_ORACLE_VELOCITY_NOISE, OracleConfig

    for section, cfg in _defaults().items():
        check_config(section, cfg)
    check_config("oracle", OracleConfig(velocity_noise=NOISY_ORACLE_VELOCITY_NOISE))  # oracle-noisy's own


def test_every_shipped_scenarios_sizes_pass():
    """The map section applies to the map the episode sized to the scenario; the episode's duration and
    renderer default to the scenario's."""
    from experiments.episode import map_config_for
    from experiments.registry import DEFAULT_PLANNER, make_planner
    from sim.scenario import load_scenario, shipped_scenarios

    for name in shipped_scenarios():
        sc = load_scenario(name)
        check_config("map", map_config_for(sc, 0.43))
        check_value("episode.duration", sc.duration)
        check_value("episode.renderer", sc.camera.renderer)
    planner = make_planner(DEFAULT_PLANNER, 0.43)  # sized for the simulated drone
    check_config("shield", planner.cfg)
    check_config("navigator", planner.planner.cfg)


# values the tests, docs and command examples set (--set, Settings, the configuration dataclasses)
USED = [
    ("shield.a_brake", 3.0), ("shield.a_brake", 2.5), ("shield.a_emergency", 6.5), ("shield.away_angle", 2.356),
    ("shield.memory", 5.0), ("shield.memory_min_age", 0.2), ("shield.drone_radius", 0.43),
    ("navigator.mpc.horizon", 30), ("navigator.mpc.horizon", 20), ("navigator.mpc.dynamic_margin", 0.15),
    ("navigator.mpc.robot_radius", 0.43), ("navigator.camera_half_fov", 0.759),
    ("navigator.block_times", [0.0, 1.0]), ("navigator.cruise_speed", 1.2), ("navigator.watch_range", 4.5),
    ("navigator.watch_range", 2.0), ("navigator.watch_range", 0.1),
    ("navigator.maneuvers.along", [-0.5, 0.0, 0.5, 1.0, 1.5, 2.0]),
    ("navigator.maneuvers.along", [-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0]),
    ("navigator.maneuvers.along", [-1.5, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5]),
    ("navigator.maneuvers.static_margin", 0.4), ("navigator.maneuvers.static_margin", 0.05),
    ("navigator.maneuvers.worst_case", 0.0), ("navigator.maneuvers.dynamic_margin", 0.15),
    ("episode.static_map", "truth"), ("episode.static_map", "depth"), ("episode.plan_rate", 5),
    ("episode.plan_rate", 20), ("episode.duration", None), ("episode.duration", 0.3), ("episode.duration", 1),
    ("episode.duration", 14.0), ("episode.max_yaw_rate", 2.5), ("episode.max_yaw_rate", 0.8),
    ("episode.frame_latency", 0), ("episode.frame_latency", 100), ("episode.renderer", "tiny"),
    ("episode.renderer", "gl"), ("episode.renderer", "egl"),
    ("map.p_hit", 0.75), ("map.origin", (-0.5, -2.5, -0.1)), ("map.size", (17.0, 5.0, 3.2)),
    ("map.origin", (-1, -1, -0.1)), ("map.size", (2.0, 1.5, 3.0)), ("map.skip_pixel", 1), ("map.margin", 0),
    ("map.local_update_range", (2.75, 5.0, 5.0)), ("map.ray_bundle_px", 0),
    ("dodt.motion.min_speed", 0), ("dodt.motion.min_speed", 0.3), ("dodt.motion.min_speed", 2.5),
    ("dodt.motion.max_speed", 4.0), ("dodt.motion.height", [0.9, 2.4]), ("dodt.motion.min_age", 0.1),
    ("dodt.motion.on_structure", 1), ("dodt.motion.enabled", False),
    ("oracle.max_range", 8), ("oracle.max_range", 6), ("oracle.accel_window", None), ("oracle.velocity_noise", 0.1),
    ("oracle.half_view", 30.0), ("oracle.half_view", 90), ("oracle.half_view", 180.0), ("oracle.memory", 0),
    ("oracle.memory", 0.5), ("oracle.confirm_time", 0.4), ("oracle.confirm_time", 0.3),
    ("dodt.name", "mine"), ("dodt.kalman.q_pos", 0.02), ("dodt.kalman.cut_half_width", 0),
    ("dodt.kalman.p0", 0.25), ("dodt.kalman.r_vel", 0.3), ("dodt.kalman.q_white", 1.0), ("dodt.kalman.r_pos", 0.01),
    ("dodt.kalman.measurement", "position"), ("dodt.kalman.position_source", "box"), ("dodt.kalman.turn_window", 0.0),
    ("dodt.ensemble.detectors", ["udepth"]), ("dodt.ensemble.detectors", ("dbscan",)),
    ("dodt.ensemble.fusion", "union"), ("dodt.ensemble.iou_threshold", 0.06),
    ("dodt.association.method", "cosine"), ("dodt.association.fallback_gate", 0.0),
    ("dodt.track.coast_time", 1.5), ("dodt.track.coast_time", 0.8), ("dodt.track.coast_time", 0.0),
    ("dodt.identification.release_span", None), ("dodt.identification.force_dynamic_span", None),
    ("dodt.identification.consistency_span", 0.0), ("dodt.voxel.occupied_threshold", 8),
    ("dodt.voxel.occupied_threshold", 2), ("dodt.voxel.threshold_reference_distance", 0.0),
    ("dodt.depth.depth_max", 5.0), ("dodt.depth.margin", 20), ("dodt.depth.skip", 3),
    ("dodt.udepth.col_scale", 0.4), ("dodt.dbscan.split_width", 0.0),
    ("dodt.learned.enabled", True), ("dodt.learned.layout", "yolov8"), ("dodt.learned.input_size", [640, 480]),
    ("dodt.learned.input_size", (640, 640)), ("dodt.learned.views", ["full", "flip"]),
    ("dodt.learned.views", ("full", "flip", "center")), ("dodt.learned.unseen_after", 0),
    ("dodt.learned.unseen_after", 0.2), ("dodt.learned.match_box", "union"), ("dodt.learned.duplicate_gate", 0.0),
    ("dodt.learned.fragment_height", 0.0), ("dodt.learned.person_box_max_height", 0.0),
    ("dodt.learned.person_match_gate", 0.0), ("dodt.learned.pixel_scale", 1.0 / 255.0),
    ("dodt.learned.letterbox", "top-left"), ("dodt.learned.channels", "bgr"), ("dodt.learned.model", "/x/y.onnx"),
]


@pytest.mark.parametrize("key, value", USED)
def test_values_in_use_pass(key, value):
    check_value(key, value)


# ------------------------------------------------------------------------------------------ (c) nonsense

NONSENSE = [  # (key, the --set text of the value)
    ("shield.a_brake", "nan"), ("shield.a_brake", "-1"), ("shield.a_brake", "1e400"), ("shield.a_brake", "0"),
    ("navigator.mpc.dt", "0"), ("navigator.mpc.horizon", "0"), ("navigator.mpc.horizon", "100000"),
    ("episode.renderer", "foo"), ("map.resolution", "1e-9"), ("map.size", "[1e9,1e9,1e9]"),
    ("episode.seen_band", "[nan,1.0]"), ("episode.seen_band", "[1.6,0.8]"), ("shield.directions", "0"),
    ("shield.speeds", "[]"), ("shield.speeds", "[nan]"), ("shield.speeds", "[0.5, nan]"),
    ("shield.v_max", "nan"), ("navigator.mpc.v_max_xy", "nan"), ("navigator.mpc.v_max_z", "nan"),
    ("shield.person_speed", "nan"), ("navigator.cruise_speed", "nan"), ("episode.max_yaw_rate", "nan"),
    ("episode.plan_rate", "inf"), ("episode.plan_rate", "0"), ("shield.memory", "inf"), ("oracle.memory", "inf"),
    ("oracle.max_range", "inf"), ("episode.launch_radius", "-1"), ("dodt.kalman.q_pos", "nan"),
    ("episode.frame_latency", "100000"), ("episode.frame_latency", "-1"), ("episode.duration", "0"),
    ("episode.static_map", "lidar"), ("dodt.kalman.model", "ukf"), ("dodt.association.method", "hungarian"),
    ("dodt.ensemble.detectors", "[]"), ("dodt.ensemble.detectors", '["udepth", "udepth"]'),
    ("dodt.learned.views", '["sideways"]'), ("dodt.learned.input_size", "[8, 8]"),
    ("dodt.udepth.blur_size", "[4, 5]"), ("dodt.learned.core_x", "[0.7, 0.3]"), ("map.p_hit", "1.0"),
    ("navigator.mpc.horizon", "2.5"), ("shield.a_brake", "true"), ("episode.render_process", "1"),
    ("map.origin", "[0.0, 0.0]"), ("oracle.noise_seed", "-1"), ("dodt.reference_rate", "0"),
]


@pytest.mark.parametrize("key, text", NONSENSE)
def test_nonsense_is_refused_naming_the_key(key, text):
    value = parse_value(text)
    with pytest.raises(ValueError, match=rf"^{re.escape(key)}: ") as e:
        check_value(key, value)
    assert "\n" not in str(e.value)


def test_none_only_where_optional_and_unknown_keys():
    check_value("episode.renderer", None)
    with pytest.raises(ValueError, match=r"^shield.a_brake: none is not allowed"):
        check_value("shield.a_brake", None)
    with pytest.raises(ValueError, match=r"^shield.nope: unknown key"):
        check_value("shield.nope", 1.0)


def test_messages_say_what_is_allowed():
    with pytest.raises(ValueError) as e:
        check_value("shield.speeds", [0.5, math.nan])
    assert str(e.value) == "shield.speeds: element 1: nan is not a number in (0, 10]"
    with pytest.raises(ValueError) as e:
        check_value("navigator.mpc.horizon", 0)
    assert str(e.value) == "navigator.mpc.horizon: 0 is not a whole number in [1, 200]"
    with pytest.raises(ValueError) as e:
        check_value("episode.renderer", "foo")
    assert str(e.value) == "episode.renderer: 'foo' is not one of auto, gl, pybullet, tiny, egl, or none"


def test_a_limit_is_built_consistent():
    for bad in (dict(lo=0.0, hi=math.inf), dict(lo=1.0, hi=0.0), dict(kind="string", lo=0.0),
                dict(kind="bool", choices=("a",)), dict(lo=0.0, hi=1.0, ordered=True), dict(kind="text")):
        with pytest.raises(ValueError):
            Limit(**bad)


# ------------------------------------------------------------------------------------------ (d) property

SCALAR_REALS = sorted(k for k, lim in LIMITS.items() if lim.kind == "number" and not lim.integer and lim.length is None)


@st.composite
def _key_and_float(draw):
    key = draw(st.sampled_from(SCALAR_REALS))
    lim = LIMITS[key]
    near = [lim.lo, lim.hi] + [math.nextafter(b, d) for b in (lim.lo, lim.hi) for d in (-math.inf, math.inf)]
    value = draw(st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from(near),
                           st.floats(lim.lo - 1.0, lim.hi + 1.0), st.sampled_from([math.nan, math.inf, -math.inf])))
    return key, value


@settings(max_examples=400, deadline=None)
@given(_key_and_float())
def test_a_number_is_accepted_iff_finite_and_inside(key_value):
    key, x = key_value
    lim = LIMITS[key]
    inside = (math.isfinite(x) and (lim.lo < x if lim.lo_open else lim.lo <= x)
              and (x < lim.hi if lim.hi_open else x <= lim.hi))
    try:
        check_value(key, x)
        accepted = True
    except ValueError as e:
        accepted = False
        assert str(e).startswith(f"{key}: ")
    assert accepted == inside, (key, x)


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(sorted(k for k, lim in LIMITS.items() if lim.kind == "number" and lim.length is not None)),
       st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=20))
def test_a_tuple_is_accepted_iff_its_length_and_every_element_are(key, xs):
    lim = LIMITS[key]
    scalar = dataclasses.replace(lim, length=None, ordered=False, distinct=False, optional=False)
    ok = (lim.length[0] <= len(xs) <= lim.length[1] and all(scalar.problem(x) is None for x in xs)
          and not (lim.ordered and any(b < a for a, b in zip(xs, xs[1:]))))
    try:
        check_value(key, xs)
        accepted = True
    except ValueError:
        accepted = False
    assert accepted == ok, (key, xs)
