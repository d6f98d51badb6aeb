"""The allowed values of every configuration key (experiments.config's sections), and their check.

``LIMITS`` maps each leaf key, dotted from its section (``"shield.a_brake"``, ``"navigator.mpc.horizon"``,
``"dodt.kalman.q_pos"``), to a Limit: its type (number, whole number, true/false, string), a finite interval
for numbers, the choices for strings, the number of elements of a tuple (each element then meets the
rest of the Limit), and whether none is allowed. ``check_value(key, value)`` raises a ConfigError (a
ValueError) of one line naming the key; NaN and +-inf are refused for every number.

How the bounds are chosen: from each field's meaning (its unit and what the code does with it, see the
dataclass' comments), wide enough that every default, every preset (dodt.presets) and every value the
tests and docs set lies inside, tight enough that a value no vehicle, camera or person has is refused,
and so is one the code would divide by zero with or allocate without bound for (a time step or a
resolution near zero, a horizon or a number of directions without end). What holds between keys (a
minimum below its maximum, the map's cells as size / resolution) is checked by the dataclasses
themselves, not here; only the two ends of a pair held in one key (``episode.seen_band``) are.

The choices of string keys are copies of the code's own lists (sim.scenario.RENDERER_CHOICES,
experiments.episode.STATIC_MAPS, dodt.learned.yolo.LAYOUTS and PREPROCESS, dodt.learned.views.VIEWS),
kept here so that this module loads without the simulator; tests/experiments/test_config_limits.py
compares them.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from numbers import Integral, Real

from experiments.config import ConfigError

KINDS = ("number", "bool", "string")


@dataclass(frozen=True)
class Limit:
    """The allowed values of one key.

    kind: "number" (int or float; whole numbers only with ``integer``), "bool" or "string";
    lo, hi: a number's finite bounds, each closed unless ``lo_open`` / ``hi_open``;
    choices: a string's allowed values (None: any string);
    length: (least, most) elements: the value is a tuple (or list) whose every element meets this Limit;
    ordered: the elements of such a tuple never decrease (a pair low, high); distinct: no element twice;
    odd: a whole number that is odd (an OpenCV kernel size);
    optional: None is allowed too."""

    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    choices: tuple[str, ...] | None = None
    length: tuple[int, int] | None = None
    optional: bool = False
    integer: bool = False
    kind: str = "number"
    ordered: bool = False
    distinct: bool = False
    odd: bool = False

    def __post_init__(self):
        if self.kind not in KINDS:
            raise ValueError(f"Limit: kind {self.kind!r} is not one of {', '.join(KINDS)}")
        if self.kind == "number":
            if self.lo is None or self.hi is None or not (math.isfinite(self.lo) and math.isfinite(self.hi)) \
                    or not self.lo <= self.hi:
                raise ValueError(f"Limit: a number needs finite bounds lo <= hi, got {self.lo!r}, {self.hi!r}")
        elif self.lo is not None or self.hi is not None or self.integer or self.odd:
            raise ValueError(f"Limit: bounds, integer and odd are for numbers, not a {self.kind}")
        if self.choices is not None and (self.kind != "string" or not self.choices):
            raise ValueError("Limit: choices are a non-empty tuple, for strings only")
        if self.length is not None and not 0 <= self.length[0] <= self.length[1]:
            raise ValueError(f"Limit: length must be (least, most) with 0 <= least <= most, got {self.length!r}")
        if (self.ordered or self.distinct) and self.length is None:
            raise ValueError("Limit: ordered and distinct are for tuples (give length)")

    # ---------------------------------------------------------------- words
    def element(self) -> str:
        """What one value (one element of a tuple) may be, in words: 'a number in (0, 20]'."""
        if self.kind == "bool":
            return "true or false"
        if self.kind == "string":
            return "any string" if self.choices is None else "one of " + ", ".join(self.choices)
        what = "an odd whole number" if self.odd else "a whole number" if self.integer else "a number"
        return f"{what} in {'(' if self.lo_open else '['}{_num(self.lo)}, {_num(self.hi)}{')' if self.hi_open else ']'}"

    def describe(self) -> str:
        """Every allowed value in words: 'a number in (0, 20]', '1 to 16 values, each a number in (0, 10]'."""
        if self.length is None:
            text = self.element()
        else:
            least, most = self.length
            count = f"{least} values" if least == most else f"{least} to {most} values"
            text = (f"{count}, each {self.element()}" + (", in increasing order" if self.ordered else "")
                    + (", none twice" if self.distinct else ""))
        return text + (", or none" if self.optional else "")

    # ---------------------------------------------------------------- checks
    def problem(self, value) -> str | None:
        """Why ``value`` is not allowed (a phrase to follow the key), or None when it is."""
        if value is None:
            return None if self.optional else f"none is not allowed; expected {self.describe()}"
        if self.length is None:
            return None if self._allows(value) else f"{_show(value)} is not {self.describe()}"
        if isinstance(value, (str, bytes)) or not isinstance(value, (tuple, list)):
            return f"{_show(value)} is not a list; expected {self.describe()}"
        least, most = self.length
        if not least <= len(value) <= most:
            return f"{len(value)} values; expected {self.describe()}"
        for i, x in enumerate(value):
            if not self._allows(x):
                return f"element {i}: {_show(x)} is not {self.element()}"
        if self.ordered and any(b < a for a, b in zip(value, value[1:])):
            return f"{_show(list(value))} is not in increasing order (low <= high)"
        if self.distinct and len(set(value)) != len(value):
            return f"{_show(list(value))} names a value twice"
        return None

    def _allows(self, x) -> bool:
        """Whether ``x`` (not None) is allowed as one value, or as one element of a tuple."""
        if self.kind == "bool":
            return isinstance(x, bool)
        if self.kind == "string":
            return isinstance(x, str) and (self.choices is None or x in self.choices)
        whole = isinstance(x, Integral) and not isinstance(x, bool)
        if isinstance(x, bool) or not isinstance(x, Real) or (self.integer and not whole):
            return False
        finite = whole or math.isfinite(x)  # a whole number is finite however large (float() could overflow)
        return (finite and (x > self.lo if self.lo_open else x >= self.lo)
                and (x < self.hi if self.hi_open else x <= self.hi) and not (self.odd and x % 2 == 0))


def _num(x) -> str:
    return str(x) if isinstance(x, Integral) else f"{x:g}"


def _show(x) -> str:
    """A value as the message shows it (nan, inf, 2.5, 'foo', [1.0, 2.0]), cut to one short line."""
    text = "nan" if isinstance(x, float) and math.isnan(x) else repr(x)
    return text if len(text) <= 60 else text[:57] + "..."


# -------------------------------------------------------------------- building the table

def _real(lo: float, hi: float, lo_open: bool = False, hi_open: bool = False, **kw) -> Limit:
    return Limit(lo, hi, lo_open, hi_open, **kw)


def _whole(lo: int, hi: int, **kw) -> Limit:
    return Limit(lo, hi, integer=True, **kw)


def _one_of(*choices: str, **kw) -> Limit:
    return Limit(kind="string", choices=choices, **kw)


def _pair(lo: float, hi: float, **kw) -> Limit:
    """Two numbers in [lo, hi], low first (an interval)."""
    return Limit(lo, hi, length=(2, 2), ordered=True, **kw)


def _triple(lo: float, hi: float, lo_open: bool = False) -> Limit:
    """Three numbers, one per axis x, y, z."""
    return Limit(lo, hi, lo_open=lo_open, length=(3, 3))


BOOL = Limit(kind="bool")
ANY_STRING = Limit(kind="string")

# the code's own lists (module docstring)
RENDERER_CHOICES = ("auto", "gl", "pybullet", "tiny", "egl")  # sim.scenario.RENDERER_CHOICES
# the named sensor rigs (sim.rig.RIGS; not imported here: it loads the simulator)
RIG_NAMES = ("front", "front_back", "surround4", "lidar", "lidar_below")
PLANNER_NAMES = ("default", "nmpc")  # the built-in planners (experiments.registry.BUILTIN_PLANNERS), default first
STATIC_MAPS = ("depth", "truth")  # the static maps an episode can fly with (EpisodeConfig.static_map)
LEARNED_LAYOUTS = ("auto", "dodt", "yolov8", "yolov5", "yolox")  # "auto" + dodt.learned.yolo.LAYOUTS
LEARNED_VIEWS = ("full", "flip", "center", "center-flip")  # dodt.learned.views.VIEWS
MAX_FRAME_LATENCY = 100  # camera periods; the command line's --frame-latency has the same limit
SEED_MAX = 2**63 - 1  # a TOML integer's largest, as the command line's seeds

# Units in the comments; "0: off" where the field's comment makes 0 turn a rule off. Common bounds: speeds
# up to 10 m/s (a drone indoors, a running person), accelerations up to 20 m/s^2 (twice g), distances
# within 50 m of the drone (the camera sees 10), durations of history up to 60 s, and spans over
# which a tracker holds frames up to 10 s (each frame of the span is kept).
_SPEED = _real(0.0, 10.0, lo_open=True)  # m/s
_SPEED0 = _real(0.0, 10.0)  # m/s, 0 allowed
_ACCEL = _real(0.0, 20.0, lo_open=True)  # m/s^2
_ACCEL0 = _real(0.0, 20.0)
_MARGIN = _real(0.0, 5.0)  # m, a clearance kept or added
_RANGE = _real(0.0, 50.0)  # m, a distance around the drone or an obstacle
_WEIGHT = _real(0.0, 1e6)  # a cost weight
_FRACTION = _real(0.0, 1.0)  # a share, probability or IoU
_SPAN = _real(0.0, 10.0)  # s, a window of frames or a look ahead
_HISTORY = _real(0.0, 60.0)  # s, how long something is remembered
_RESOLUTION = _real(0.02, 1.0)  # m per voxel: (1 / 0.02)^3 cells per cubic metre at most
_HEIGHT = _real(-10.0, 20.0)  # m, world z of a horizontal plane

LIMITS: dict[str, Limit] = {
    # ---- episode (experiments.episode.EpisodeConfig)
    # Hz; at least one plan in 10 s (the episode's plan interval is 1 / (rate x control step))
    "episode.plan_rate": _real(0.1, 1000.0),
    "episode.map_every": _whole(1, 100),  # camera frames per map update
    "episode.max_yaw_rate": _real(0.0, 10.0),  # rad/s; 0: the heading never turns
    "episode.accel_lead": _real(0.0, 1.0),  # s
    "episode.map_snapshot_period": _real(0.01, 3600.0),  # s
    "episode.duration": _real(0.0, 3600.0, lo_open=True, optional=True),  # s, as experiments.config.check
    "episode.static_map": _one_of(*STATIC_MAPS),
    "episode.rig": _one_of(*RIG_NAMES, optional=True),
    "episode.frame_latency": _whole(0, MAX_FRAME_LATENCY),  # camera periods, each frame held in memory
    "episode.render_process": BOOL,
    "episode.seen_band": _pair(0.0, 10.0),  # m, world z from the floor
    "episode.launch_radius": _real(0.0, 50.0),  # m; 0: nothing seen at the start
    "episode.renderer": _one_of(*RENDERER_CHOICES, optional=True),
    # ---- shield (planner.shield.ShieldConfig). Its motions take ceil(commit_time / dt) + ceil(v_max /
    # (a_brake dt)) + 2 steps (planner.shield.candidates.horizon_steps), for 1 + len(speeds) x directions motions:
    # dt, a_brake, speeds and directions are bounded so that those arrays stay within some 100 MB
    "shield.dt": _real(0.02, 1.0),  # s
    "shield.commit_time": _real(0.0, 10.0),  # s
    "shield.a_brake": _real(0.5, 20.0),  # m/s^2
    "shield.a_emergency": _ACCEL,
    "shield.a_max": _ACCEL,
    "shield.v_max": _SPEED,
    "shield.speeds": _real(0.0, 10.0, lo_open=True, length=(1, 16)),  # m/s
    "shield.directions": _whole(1, 72),  # every 5 degrees at most
    "shield.drone_radius": _real(0.0, 5.0, lo_open=True),  # m
    "shield.static_margin": _MARGIN,
    "shield.person_margin": _MARGIN,
    "shield.person_body": _real(0.0, 2.0),  # m, a person's radius
    "shield.person_accel": _ACCEL0,
    "shield.person_speed": _SPEED0,
    "shield.sigmas": _real(0.0, 10.0),  # standard deviations
    "shield.at_rest": _real(0.0, 2.0),  # m/s
    "shield.away_angle": _real(0.0, math.pi),  # rad off the motion
    "shield.lag": _real(0.0, 5.0),  # s
    "shield.memory": _HISTORY,
    "shield.memory_min_age": _HISTORY,
    "shield.memory_merge": _real(0.0, 10.0),  # m
    "shield.band": _MARGIN,  # m from the flight altitude
    "shield.w_way": _WEIGHT,
    "shield.way_look": _SPAN,
    "shield.hold_speed": _SPEED0,
    "shield.unobserved_is_blocked": BOOL,
    "shield.unobserved_band": _real(0.0, 2.0),  # m
    "shield.hold_reanchor": _real(0.0, 10.0),  # m
    # ---- navigator (planner.nominal.navigator.NavigatorConfig)
    "navigator.cruise_speed": _SPEED,
    "navigator.goal_decel": _ACCEL,
    "navigator.band_half_height": _MARGIN,
    "navigator.path_period": _HISTORY,  # s; 0: a path search every plan
    "navigator.static_radius": _RANGE,
    "navigator.static_band": _real(0.0, 10.0),  # m
    "navigator.block_times": _real(0.0, 10.0, length=(1, 16)),  # s ahead
    "navigator.look_ahead": _real(0.0, 50.0, lo_open=True),  # m along the path
    "navigator.use_geofence": BOOL,
    "navigator.guide_look_ahead": _real(0.0, 50.0, lo_open=True),  # m along the path
    "navigator.heading_look_time": _real(0.0, 10.0, lo_open=True),  # s
    "navigator.camera_half_fov": _real(0.0, math.pi, lo_open=True, optional=True),  # rad; none: the camera's
    "navigator.fov_margin": _real(0.0, math.pi),  # rad
    "navigator.watch_range": _RANGE,
    "navigator.watch_times": _real(0.0, 10.0, length=(1, 16)),  # s ahead
    "navigator.stall_window": _real(0.0, 60.0, lo_open=True),  # s
    "navigator.stall_progress": _RANGE,
    "navigator.stall_radius": _real(0.0, 5.0, lo_open=True, optional=True),  # m; none: never
    # ---- navigator.nmpc (planner.mpc.config.NMPCConfig)
    "navigator.nmpc.stride": _whole(1, 100),  # MPC steps per NMPC step (at most the horizon: checked on build)
    "navigator.nmpc.max_iter": _whole(1, 10000),
    "navigator.nmpc.tol": _real(0.0, 1.0, lo_open=True),
    # ---- navigator.maneuvers (planner.nominal.maneuvers.ManeuverConfig). Candidates: (len(along) x len(across))^2,
    # each of mpc.horizon steps: 12 x 12 targets give 20736
    "navigator.maneuvers.along": _real(-10.0, 10.0, length=(1, 12)),  # m/s
    "navigator.maneuvers.across": _real(-10.0, 10.0, length=(1, 12)),  # m/s
    "navigator.maneuvers.t_switch": _SPAN,
    "navigator.maneuvers.p_keep": _FRACTION,
    "navigator.maneuvers.p_stop": _FRACTION,
    "navigator.maneuvers.p_turn": _FRACTION,
    "navigator.maneuvers.turn_rate": _real(0.0, 10.0),  # rad/s
    "navigator.maneuvers.walk_speed": _pair(0.0, 10.0),  # m/s
    "navigator.maneuvers.start_accel": _ACCEL0,
    "navigator.maneuvers.stop_decel": _ACCEL,  # divides a speed
    "navigator.maneuvers.standing": _SPEED0,
    "navigator.maneuvers.worst_case": _real(0.0, 100.0),  # weight of the worst future beside the mean
    "navigator.maneuvers.w_goal": _WEIGHT,
    "navigator.maneuvers.w_hit": _WEIGHT,
    "navigator.maneuvers.w_near": _WEIGHT,
    "navigator.maneuvers.dynamic_margin": _MARGIN,
    "navigator.maneuvers.w_static": _WEIGHT,
    "navigator.maneuvers.static_margin": _MARGIN,
    "navigator.maneuvers.brake": _real(0.1, 20.0),  # m/s^2; the stopping distance is v^2 / (2 brake)
    "navigator.maneuvers.t_full": _SPAN,
    "navigator.maneuvers.t_fade": _SPAN,  # s; 0: no weight after t_full
    "navigator.maneuvers.react_delay": _SPAN,
    "navigator.maneuvers.evade_accel": _ACCEL0,
    "navigator.maneuvers.t_full_alt": _SPAN,
    "navigator.maneuvers.t_fade_alt": _SPAN,
    "navigator.maneuvers.max_extent": _real(0.0, 10.0),  # m
    "navigator.maneuvers.w_keep": _WEIGHT,
    "navigator.maneuvers.keep_steps": _whole(0, 200),  # steps of the horizon
    "navigator.maneuvers.w_acc": _WEIGHT,
    "navigator.maneuvers.band_half_height": _MARGIN,
    "navigator.maneuvers.near_goal": _RANGE,
    "navigator.maneuvers.approach_range": _RANGE,
    # ---- navigator.mpc (planner.mpc.config.MPCConfig)
    "navigator.mpc.horizon": _whole(1, 200),  # steps
    "navigator.mpc.dt": _real(0.01, 1.0),  # s
    "navigator.mpc.v_max_xy": _real(0.1, 10.0),  # m/s; above backoff, or the QP's bounds cross
    "navigator.mpc.v_max_z": _real(0.1, 10.0),
    "navigator.mpc.a_max_xy": _real(0.1, 20.0),  # m/s^2
    "navigator.mpc.a_max_z": _real(0.1, 20.0),
    "navigator.mpc.z_min": _real(0.0, 10.0),  # m, world z
    "navigator.mpc.z_max": _real(0.0, 10.0),
    "navigator.mpc.w_pos": _WEIGHT,
    "navigator.mpc.w_vel": _WEIGHT,
    "navigator.mpc.w_terminal": _WEIGHT,
    "navigator.mpc.w_acc": _WEIGHT,
    "navigator.mpc.w_jerk": _WEIGHT,
    "navigator.mpc.w_slack_lin": _WEIGHT,
    "navigator.mpc.w_slack_quad": _WEIGHT,
    "navigator.mpc.static_slack_scale": _real(0.0, 1000.0),
    "navigator.mpc.robot_radius": _real(0.0, 5.0, lo_open=True),  # m
    "navigator.mpc.dynamic_margin": _MARGIN,
    "navigator.mpc.static_margin": _MARGIN,
    "navigator.mpc.z_std": _real(0.0, 10.0),  # standard deviations
    "navigator.mpc.dynamic_range": _RANGE,
    "navigator.mpc.max_dynamic": _whole(0, 64),  # QP rows per step
    "navigator.mpc.static_per_step": _whole(0, 64),  # QP rows per step
    "navigator.mpc.static_radius": _RANGE,
    "navigator.mpc.voxel_size": _RESOLUTION,
    "navigator.mpc.side_bias": _MARGIN,
    "navigator.mpc.relative_side": BOOL,
    "navigator.mpc.geofence_margin": _MARGIN,
    "navigator.mpc.geofence_scale": _real(0.0, 1000.0),
    "navigator.mpc.iterations": _whole(1, 20),
    "navigator.mpc.warm_start": BOOL,
    "navigator.mpc.rho": _real(1e-6, 1e6),  # OSQP's ADMM step, > 0
    "navigator.mpc.eps_abs": _real(0.0, 1.0, lo_open=True),
    "navigator.mpc.eps_rel": _real(0.0, 1.0, lo_open=True),
    "navigator.mpc.max_iter": _whole(1, 1_000_000),
    "navigator.mpc.max_prim_res": _real(0.0, 10.0),
    "navigator.mpc.backoff": _real(0.0, 0.05),  # m/s, m; below v_max's least
    # ---- map (planner.map.voxel_map.MapConfig; the probabilities' order among each other is its own check)
    "map.resolution": _RESOLUTION,
    "map.origin": _triple(-1000.0, 1000.0),  # m, world
    "map.size": _triple(0.0, 200.0, lo_open=True),  # m per axis
    "map.p_hit": _real(0.5, 1.0, lo_open=True, hi_open=True),
    "map.p_miss": _real(0.0, 0.5, lo_open=True, hi_open=True),
    "map.p_min": _real(0.0, 0.5, lo_open=True, hi_open=True),
    "map.p_max": _real(0.0, 1.0, lo_open=True, hi_open=True),
    "map.p_occ": _real(0.0, 1.0, lo_open=True, hi_open=True),
    "map.unknown_offset": _real(1e-4, 10.0),  # log-odds; above 0: unknown and free must differ in float32
    "map.depth_min": _real(0.0, 20.0),  # m
    "map.depth_max": _real(0.0, 50.0, lo_open=True),  # m
    "map.hole_window": _whole(0, 8),  # px; 0: the reference's rule (each hole scans (2r+1)^2 pixels)
    "map.raycast_max": _real(0.0, 50.0, lo_open=True),  # m
    "map.skip_pixel": _whole(1, 64),  # px
    "map.ray_bundle_px": _whole(0, 256),  # px; 0: the reference's rule
    "map.margin": _whole(0, 500),  # px
    "map.local_update_range": _triple(0.0, 200.0, lo_open=True),  # m per axis
    "map.robot_size": _triple(0.0, 10.0, lo_open=True),  # m per axis
    "map.dynamic_margin": _MARGIN,
    "map.dynamic_history": _whole(1, 300),  # frames of freed regions kept
    "map.static_after": _whole(0, 100_000),  # updates; 0: off
    "map.protect_before": _whole(0, 100_000),  # updates; 0: off
    # ---- dodt (dodt.config.DODTConfig, the preset's)
    "dodt.name": ANY_STRING,
    "dodt.reference_rate": _real(1.0, 1000.0),  # Hz, a camera's frame rate
    "dodt.depth.depth_min": _real(0.0, 20.0),  # m
    "dodt.depth.depth_max": _real(0.0, 50.0, lo_open=True),  # m
    "dodt.depth.margin": _whole(0, 500),  # px
    "dodt.depth.skip": _whole(1, 64),  # px
    "dodt.depth.max_frame_gap": _real(0.0, 3600.0),  # s
    "dodt.depth.max_time_jump": _real(0.0, 86400.0, lo_open=True),  # s
    "dodt.depth.confirm_jump_frames": _whole(1, 1000),
    "dodt.voxel.resolution": _RESOLUTION,
    "dodt.voxel.occupied_threshold": _whole(1, 10_000),  # points per voxel
    "dodt.voxel.threshold_reference_distance": _RANGE,  # m; 0: a fixed threshold
    "dodt.voxel.min_occupied_threshold": _whole(1, 10_000),
    "dodt.voxel.ground_height": _HEIGHT,
    "dodt.voxel.ceiling_height": _HEIGHT,
    "dodt.voxel.local_range": _real(0.0, 50.0, lo_open=True),  # m
    "dodt.udepth.col_scale": _real(0.05, 1.0),  # image columns kept: a 640 px image keeps 32 at least
    "dodt.udepth.row_downsample": _whole(1, 64),
    "dodt.udepth.min_dist": _real(0.0, 10.0),  # m
    "dodt.udepth.threshold_point": _whole(0, 1000),
    "dodt.udepth.min_line_length": _whole(0, 1000),  # U-map cells
    "dodt.udepth.min_area": _whole(0, 100_000),  # U-map cells
    "dodt.udepth.occlusion_factor": _real(0.0, 10.0),
    "dodt.udepth.continuity_rows": _whole(0, 1000),
    "dodt.udepth.blur_size": Limit(1, 51, integer=True, odd=True, length=(2, 2)),  # OpenCV: odd sizes
    "dodt.udepth.blur_sigma": _real(0.0, 50.0),  # px; 0: from the size (OpenCV)
    "dodt.udepth.extent_percentile": _real(0.0, 50.0, hi_open=True),  # the box spans p to 100 - p
    "dodt.udepth.min_height": _real(0.0, 10.0),  # m
    "dodt.udepth.height_filter": BOOL,
    "dodt.lidar.max_range": _real(0.5, 100.0),  # m
    "dodt.lidar.min_range": _real(0.0, 5.0),  # m
    "dodt.lidar.wall_margin": _real(0.0, 2.0),  # m
    "dodt.lidar.voxel": _real(0.02, 1.0),  # m
    "dodt.lidar.eps": _real(0.0, 5.0, lo_open=True),  # m
    "dodt.lidar.min_points": _whole(1, 10_000),
    "dodt.lidar.max_footprint": _real(0.1, 100.0),  # m
    "dodt.lidar.structure_fraction": _FRACTION,
    "dodt.lidar.floor_tolerance": _real(0.0, 2.0),  # m
    "dodt.lidar.vote_span": _real(0.0, 5.0, lo_open=True),  # s
    "dodt.lidar.vote_velocity": _real(0.0, 10.0),  # m/s
    "dodt.lidar.face_cos": _real(-1.0, 1.0, optional=True),  # cosine; None: every point votes
    "dodt.lidar.vote_scans": _whole(1, 20),
    "dodt.lidar.field_margin": _real(0.0, 2.0, optional=True),  # m; None: every point votes
    "dodt.lidar.min_field_share": _FRACTION,
    "dodt.dbscan.eps": _real(0.0, 5.0, lo_open=True),  # m
    "dodt.dbscan.min_points": _whole(1, 10_000),
    "dodt.dbscan.min_size_xy": _real(0.0, 10.0),  # m
    "dodt.dbscan.split_width": _RANGE,  # m; 0: off
    "dodt.dbscan.split_bin": _real(0.01, 1.0),  # m; a cluster is counted in slices this wide
    "dodt.dbscan.split_valley_ratio": _FRACTION,
    "dodt.dbscan.split_min_part": _real(0.0, 10.0),  # m
    "dodt.ensemble.detectors": _one_of("udepth", "dbscan", length=(1, 2), distinct=True),
    "dodt.ensemble.iou_threshold": _FRACTION,
    "dodt.ensemble.fusion": _one_of("paper", "union"),
    "dodt.ensemble.complete_depth": _real(0.0, 10.0),  # m; 0: off
    "dodt.association.method": _one_of("feature", "cosine", "center"),
    "dodt.association.similarity_threshold": _FRACTION,  # exp(-d^2) lies in (0, 1]
    "dodt.association.position_scale": _real(0.0, 10.0, lo_open=True),  # m; the features are divided by
    "dodt.association.size_scale": _real(0.0, 10.0, lo_open=True),  # these scales
    "dodt.association.count_scale": _real(0.0, 10.0, lo_open=True),
    "dodt.association.spread_scale": _real(0.0, 10.0, lo_open=True),
    "dodt.association.center_gate": _RANGE,
    "dodt.association.fallback_gate": _RANGE,  # m; 0: off
    "dodt.association.cosine_threshold": _real(-1.0, 1.0),  # a cosine
    "dodt.kalman.model": _one_of("ca", "cv"),
    "dodt.kalman.p0": _real(0.0, 1000.0, lo_open=True),  # initial covariance
    "dodt.kalman.q_pos": _real(0.0, 1000.0),  # process noise per frame at reference_rate
    "dodt.kalman.q_vel": _real(0.0, 1000.0),
    "dodt.kalman.q_acc": _real(0.0, 1000.0),
    "dodt.kalman.r_pos": _real(0.0, 1000.0, lo_open=True),  # measurement noise
    "dodt.kalman.r_vel": _real(0.0, 1000.0, lo_open=True),
    "dodt.kalman.r_acc": _real(0.0, 1000.0, lo_open=True),
    "dodt.kalman.averaging_time": _real(0.0, 10.0, lo_open=True),  # s of pseudo-measurements
    "dodt.kalman.measurement": _one_of("paper", "position"),
    "dodt.kalman.position_source": _one_of("box", "mean", "median"),
    "dodt.kalman.same_kind_differences": BOOL,
    "dodt.kalman.turn_window": _SPAN,  # s; 0: off
    "dodt.kalman.turn_min_speed": _SPEED0,
    "dodt.kalman.q_white": _real(0.0, 1000.0),  # spectral density
    "dodt.kalman.cut_half_width": _MARGIN,  # m; 0: off
    "dodt.track.coast_time": _HISTORY,  # s; 0: dropped when missed
    "dodt.track.seen_through_after": _HISTORY,
    "dodt.track.seen_through_fraction": _FRACTION,
    "dodt.track.seen_through_margin": _real(0.0, 10.0),  # m
    "dodt.track.max_coast_speed": _SPEED,
    "dodt.track.max_speed": _real(0.0, 10.0, lo_open=True, optional=True),  # m/s; none: unbounded
    "dodt.track.jump_margin": _real(0.0, 10.0, optional=True),  # m; none: never re-initialised
    "dodt.track.duplicate_radius": _real(0.0, 5.0, optional=True),  # m; none: off
    "dodt.track.wall_clearance": _real(0.0, 10.0, optional=True),  # m
    "dodt.track.camera_body_radius": _real(0.0, 5.0, optional=True),  # m; none: off
    "dodt.track.output_history": _HISTORY,
    "dodt.track.size_smoothing": _FRACTION,  # weight per frame
    "dodt.identification.method": _one_of("voting", "velocity"),
    "dodt.identification.vote_span": _SPAN,
    "dodt.identification.velocity_threshold": _SPEED0,
    "dodt.identification.vote_velocity": _SPEED0,
    "dodt.identification.vote_ratio": _FRACTION,
    "dodt.identification.max_skip_ratio": _FRACTION,
    "dodt.identification.max_point_speed": _SPEED,
    "dodt.identification.max_vote_points": _whole(0, 1_000_000),  # 0: all
    "dodt.identification.max_vote_extent": _RANGE,  # m; 0: all voted on
    "dodt.identification.range_margin": _real(0.0, 10.0),  # m
    "dodt.identification.fov_margin_px": _real(0.0, 1000.0),  # px
    "dodt.identification.consistency_span": _SPAN,
    "dodt.identification.release_span": _real(0.0, 10.0, optional=True),  # s
    "dodt.identification.force_dynamic_span": _real(0.0, 10.0, optional=True),  # s
    "dodt.identification.force_dynamic_fraction": _FRACTION,
    "dodt.identification.constrain_size": BOOL,
    "dodt.identification.target_size": _triple(0.0, 10.0, lo_open=True),  # m
    "dodt.identification.target_size_tolerance": _real(0.0, 10.0),  # m
    # ---- dodt.motion (dodt.config.MotionConfig)
    "dodt.motion.enabled": BOOL,
    "dodt.motion.min_speed": _SPEED0,
    "dodt.motion.max_speed": _SPEED0,
    "dodt.motion.height": _pair(0.0, 10.0),  # m, box height
    "dodt.motion.max_footprint": _real(0.0, 50.0, lo_open=True),  # m
    "dodt.motion.min_age": _HISTORY,
    "dodt.motion.on_structure": _FRACTION,
    "dodt.motion.wall_margin": _real(0.0, 10.0),  # m
    "dodt.motion.bottom_edge_tolerance": _real(0.0, 10.0),  # m
    "dodt.learned.enabled": BOOL,
    "dodt.learned.model": ANY_STRING,  # a path; "": the shipped model
    "dodt.learned.layout": _one_of(*LEARNED_LAYOUTS),
    "dodt.learned.person_class": _whole(0, 9999),  # a class index of the model's output
    "dodt.learned.input_size": _whole(32, 4096, length=(2, 2), optional=True),  # px (width, height)
    "dodt.learned.channels": _one_of("rgb", "bgr", optional=True),
    "dodt.learned.pixel_scale": _real(0.0, 1.0, lo_open=True, optional=True),  # 1/255 or 1
    "dodt.learned.letterbox": _one_of("center", "top-left", "none", optional=True),
    "dodt.learned.score_threshold": _real(0.0, 1.0, optional=True),
    "dodt.learned.nms_iou": _FRACTION,
    "dodt.learned.soft_nms_sigma": _real(0.0, 10.0),  # 0: NMS at nms_iou
    "dodt.learned.threads": _whole(1, 256),
    "dodt.learned.views": _one_of(*LEARNED_VIEWS, length=(1, len(LEARNED_VIEWS)), distinct=True),
    "dodt.learned.mad_n": _real(0.0, 100.0, lo_open=True),  # MADs
    "dodt.learned.margin_px": _whole(0, 1000),  # px
    "dodt.learned.core_x": _pair(0.0, 1.0),  # fractions of the box's width
    "dodt.learned.core_y": _pair(0.0, 1.0),  # fractions of its height
    "dodt.learned.depth_percentile": _real(0.0, 100.0),
    "dodt.learned.min_depth_pixels": _whole(1, 1_000_000),
    "dodt.learned.occluder_margin": _real(0.0, 1.0, optional=True),  # fraction of a box; None: off
    "dodt.learned.occluder_depth_margin": _real(0.0, 10.0),  # m
    "dodt.learned.max_person_height": _real(0.0, 10.0, lo_open=True, optional=True),  # m; divides
    "dodt.learned.max_lift_range": _real(0.0, 100.0, lo_open=True, optional=True),  # m
    "dodt.learned.depth_min": _real(0.0, 20.0),  # m
    "dodt.learned.depth_max": _real(0.0, 100.0, lo_open=True),  # m
    "dodt.learned.min_thickness": _real(0.0, 10.0),  # m
    "dodt.learned.center_behind_median": _real(0.0, 10.0),  # m
    "dodt.learned.person_size": _triple(0.0, 10.0, lo_open=True),  # m
    "dodt.learned.overwrite_distance": _real(0.0, 100.0),  # m
    "dodt.learned.iou_threshold": _FRACTION,
    "dodt.learned.match_box": _one_of("fused", "union"),
    "dodt.learned.duplicate_gate": _RANGE,  # m; 0: off
    "dodt.learned.person_match_gate": _RANGE,  # m; 0: always
    "dodt.learned.person_box_max_height": _real(0.0, 20.0),  # m; 0: no bound
    "dodt.learned.fragment_height": _FRACTION,  # of the learned box; 0: off
    "dodt.learned.person_span": _SPAN,
    "dodt.learned.person_fraction": _FRACTION,
    "dodt.learned.cut_boxes_vote": BOOL,
    "dodt.learned.far_coast_time": _HISTORY,  # s; 0: as any track
    "dodt.learned.unseen_after": _HISTORY,  # s; 0: never
    "dodt.learned.unseen_iou": _FRACTION,
    "dodt.learned.unseen_occluder_fraction": _FRACTION,
    # ---- oracle (experiments.perception_modes.OracleConfig)
    "oracle.max_range": _real(0.0, 100.0, lo_open=True),  # m
    "oracle.half_view": _real(0.0, 180.0, lo_open=True, optional=True),  # deg
    "oracle.memory": _HISTORY,
    "oracle.confirm_time": _HISTORY,
    "oracle.accel_window": _real(0.0, 10.0, lo_open=True, optional=True),  # s
    "oracle.velocity_noise": _SPEED0,  # m/s per axis
    "oracle.noise_time": _real(0.0, 3600.0, lo_open=True),  # s, a correlation time (divides)
    "oracle.noise_seed": _whole(0, SEED_MAX),
    "oracle.line_of_sight": BOOL,
}


def limit(key: str) -> Limit:
    """The Limit of a dotted key; ConfigError naming it when there is none."""
    try:
        return LIMITS[key]
    except KeyError:
        raise ConfigError(f"{key}: unknown key; no limits are known for it") from None


def check_value(key: str, value) -> None:
    """Raise ConfigError (a ValueError) naming ``key`` when ``value`` is not allowed for it."""
    why = limit(key).problem(value)
    if why is not None:
        raise ConfigError(f"{key}: {why}")


def check_config(section: str, cfg) -> None:
    """check_value on every leaf field of ``cfg``, a section's dataclass (nested ones walked into)."""
    for f in dataclasses.fields(cfg):
        v = getattr(cfg, f.name)
        key = f"{section}.{f.name}"
        if dataclasses.is_dataclass(v):
            check_config(key, v)
        else:
            check_value(key, v)
