"""Configuration of every DODT component, with defaults and where each comes from.

"paper" = Xu et al., RA-L 2024 (shared/reference/dodt-paper.tex); "ref" = the authors' ROS code
(onboard_detector cfg/detector_param.yaml, see shared/reference/dodt-reference-code.md);
"ours" = chosen here, with the reason beside it. Ablations and baselines are configurations
(dodt.presets), not forks of the code.

Time, not frames: every history window of the pipeline (the cloud voted against, the span of the
pseudo-measurements, the consistency of candidates, the hysteresis, the person label, when a
coasting track is checked) is a span of seconds, so one configuration serves a camera at any
frame rate. The reference code counts frames of its 30 Hz timers; each span below is that count
at 30 Hz (a window of n frames spans n - 1 frame periods), counted in frames at the measured
frame period (dodt.windows). Per-frame
constants (the process noise Q, the size smoothing) are given for one frame at
``DODTConfig.reference_rate`` and scaled by dt x that rate.
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class DepthConfig:
    depth_min: float = 0.5  # m, ref depth_min_value
    # m; ref depth_max_value 5.0. Ours 5.5: with 5.0 a person 4.5-5 m away (inside the recall
    # metric's 5 m) loses its far side and its votes (points near the range's end are not voted on).
    # It needs the U-depth height filter (UDepthConfig.height_filter): without it the floor made
    # one corridor-wide box at 5.5 m
    depth_max: float = 5.5
    margin: int = 10  # px border skipped, ref depth_filter_margin
    skip: int = 2  # every skip-th row and column, ref depth_skip_pixel
    max_frame_gap: float = 0.5  # s; a gap longer than this and than the coasting time restarts the tracks (ours)
    # s; a stamp farther ahead than this of the last processed frame is taken for a corrupt stamp and
    # the frame is skipped (counted as skipped_time), unless the next frames confirm the jump: a
    # single absurd stamp (say 1e300) would otherwise make every later frame look older (ours)
    max_time_jump: float = 10.0
    confirm_jump_frames: int = 3  # frames in a row whose stamps continue a jump make it the new time


@dataclass(frozen=True)
class VoxelConfig:
    resolution: float = 0.1  # m, ref (hard-coded)
    # ref voxel_occupied_thresh is 15; ours is 6: the simulated humanoid's limbs are thinner than a
    # real person's, and 15 leaves 20 points on a person at 4.5 m where 6 keeps 58
    occupied_threshold: int = 6  # points per voxel
    # ours: the threshold holds at this distance and scales with (this / distance)^2, as the
    # number of pixels a voxel covers does; 0 keeps it fixed (the reference code)
    threshold_reference_distance: float = 3.0
    min_occupied_threshold: int = 4
    ground_height: float = 0.2  # m, points below are dropped, ref ground_height
    ceiling_height: float = 2.8  # m, points above are dropped (ours: the ref has no ceiling filter)
    local_range: float = 5.5  # m around the camera; ref localSensorRange 5.0, ours as depth_max


@dataclass(frozen=True)
class UDepthConfig:
    """ref uvDetector.cpp constructor constants."""

    col_scale: float = 0.5
    row_downsample: int = 4  # U-map bins = image rows / row_downsample
    min_dist: float = 0.01  # m
    # ref: threshold_point 3, line length 6, blur 5x9 sigma 10. Ours: 1, 3, 3x5 sigma 1.5: the
    # simulated humanoid is thin, and the reference values miss many of the visible people within
    # 5 m that these find (the ensemble with DBSCAN removes the extra boxes)
    threshold_point: int = 1  # a U-map cell counts if >= threshold_point * row_downsample
    min_line_length: int = 3  # U-map cells
    min_area: int = 25  # U-map cells (width x bins)
    occlusion_factor: float = 1.3  # far = near + 1.3 * thickness
    continuity_rows: int = 15  # rows of continuous depth that confirm a pixel (ref num_check)
    blur_size: tuple[int, int] = (3, 5)  # GaussianBlur (width, height)
    blur_sigma: float = 1.5
    extent_percentile: float = 2.0  # box from the 2nd-98th percentile of its points (ours: robust to noise)
    min_height: float = 0.2  # m; flatter boxes are floor patches, dropped (ours)
    # ours: pixels whose world height is below the ground or above the ceiling height (the voxel
    # filter's) stay out of the U-depth map. With our low cell threshold the floor's nearest band
    # (several image rows per depth bin) made map lines across the whole view that joined the
    # corridor's walls into one box; with a 5.5 m depth range that box swallowed the people
    height_filter: bool = True


@dataclass(frozen=True)
class DBSCANConfig:
    # ref: epsilon 0.1 compared with a *squared* distance, so the effective radius is sqrt(0.1) = 0.32 m
    eps: float = 0.3  # m, true distance
    min_points: int = 8  # ref dbscan_min_points_cluster is 10 (with its 15-point voxels); ours 8
    min_size_xy: float = 0.1  # m, boxes are at least this wide, ref
    # ours: a cluster wider than split_width (m, horizontally) is cut where its points, counted in
    # split_bin-wide slices along its long horizontal axis, fall to a valley of at most
    # split_valley_ratio of the peaks on both sides: two people walking side by side, linked by
    # an arm within eps, are two obstacles (0 turns it off). 0.8 / 0.45 split such pairs at 4-5 m
    # too, where fewer points show the valley
    split_width: float = 0.8
    split_bin: float = 0.1  # m
    split_valley_ratio: float = 0.45
    split_min_part: float = 0.2  # m, each part at least this long along the axis


@dataclass(frozen=True)
class EnsembleConfig:
    detectors: tuple[str, ...] = ("udepth", "dbscan")  # one name: that detector alone (w/o Ens)
    iou_threshold: float = 0.05  # ref filtering_BBox_IOU_threshold (the paper gives no value)
    fusion: str = "paper"  # paper: max dimensions, mean position; union: the ref code's union box
    # ours: boxes seen from the front are extended away from the camera to be as deep as they
    # are wide, up to this many metres (0 turns it off); see dodt.geometry.complete_hidden_depth
    complete_depth: float = 0.6


@dataclass(frozen=True)
class AssociationConfig:
    method: str = "feature"  # feature (paper), cosine (ref code), center (w/o FAT and baselines)
    similarity_threshold: float = 0.05  # exp(-d^2) > 0.05 <=> d^2 < 3 (ours; the paper gives no value)
    # Normalisation scales of the feature differences (ours; the paper normalises without saying how):
    position_scale: float = 0.4  # m, grown by the track's predicted position uncertainty
    size_scale: float = 0.5  # m
    count_scale: float = 0.6  # relative difference of point counts
    spread_scale: float = 0.15  # m, point standard deviation
    center_gate: float = 1.0  # m, centre-distance association's largest match distance
    # ours: a second stage matches what the features left unmatched by predicted position within
    # this gate (+2 sigma of the prediction); 0 turns it off
    fallback_gate: float = 0.4
    cosine_threshold: float = 0.9  # ref default similarity threshold for the cosine variant


@dataclass(frozen=True)
class KalmanConfig:
    model: str = "ca"  # ca: constant acceleration (paper), cv: constant velocity (baselines)
    # ours 4.0 (ref e_p 0.25): a new track's velocity prior of 0.5 m/s around zero held a walking
    # person's filtered speed under T_vel for several frames; p0 = 4 and r_vel = 0.1 let the
    # pseudo-measurements take over sooner
    p0: float = 4.0
    q_pos: float = 0.01  # ref e_q_pos
    q_vel: float = 0.05  # ref e_q_vel
    q_acc: float = 0.05  # ref e_q_acc
    r_pos: float = 0.04  # ref e_r_pos
    r_vel: float = 0.1  # ref e_r_vel is 0.3; see p0
    r_acc: float = 0.6  # ref e_r_acc
    averaging_time: float = 10 / 30  # s; pseudo-measurements span up to this, ref averaging_frames 10 at 30 Hz
    # paper: position, velocity and acceleration "measured" (pseudo-measurements, H = I);
    # position: only the position is measured and the model's white noise (q_white) drives it
    measurement: str = "paper"
    # the point measured: "box" centre (paper), or the "mean" or "median" of the obstacle's points
    # (ours: limbs swing the box more than the body). The points are voxel centroids near a 0.1 m
    # lattice, so their median moves in steps and the mean does not
    position_source: str = "mean"
    # ours: the pseudo-measured velocity (a difference over up to averaging_time) is the
    # velocity of the middle of its span, which on a turn points turn rate x span / 2 behind.
    # It is rotated forward by the sustained turn rate, measured over turn_window seconds
    # (dodt.tracker.Track._turn_compensated: the two halves of the window must turn the same way, so
    # that a corner already turned or the body's sway gives none); 0 turns it off (the paper)
    # ours: velocity pseudo-measurements difference a learned box's anchor against the oldest learned
    # one in the window, and a cluster's against a cluster's, where the window holds one; and never
    # across sensors (with nothing from the detection's sensor in the window, the position alone is
    # measured). False: against the oldest observation in the window, whatever its kind or sensor
    same_kind_differences: bool = True
    turn_window: float = 1.0  # s
    turn_min_speed: float = 0.3  # m/s; slower, the heading says little
    q_white: float = 4.0  # (m/s^3)^2 s for CA, (m/s^2)^2 s for CV, with measurement = "position"
    # ours: a detection cut by the image's left or right edge is measured from its side inside the
    # view, at the distance from that side to the anchor measured while the whole obstacle was in
    # view, or this half width (m) for a track that has not been seen whole (dodt.view_edge); 0: the
    # cut detection's own anchor (the paper)
    cut_half_width: float = 0.25


@dataclass(frozen=True)
class TrackConfig:
    coast_time: float = 1.0  # s a track survives without detections on its prediction (beyond the paper)
    # a coasting track is dropped when, this long after its last detection, this fraction of its image
    # region (or of the LiDAR's returns through its box) is seen this far behind where it should be (it
    # is not there; ours). Checked sooner, the test drops people who only stepped off the prediction
    seen_through_after: float = 7 / 30  # s: 7 missed frames at 30 Hz
    seen_through_fraction: float = 0.75
    seen_through_margin: float = 0.3  # m
    # a person track (dynamic at once by the learned detector's label) that misses its detection
    # while its filtered speed is above this is dropped, not coasted (ours): people walk at up to
    # 1.6 m/s here, and such a speed comes from the first noisy boxes of a young track (a learned
    # box lifted 0.1 m apart in two frames is 3 m/s), and the reports of such coasting tracks lie
    # off every person. Other tracks are left alone: the coasting tracks that fast in the closed
    # loop are nearly all static-labelled pieces of wall seen from the moving drone
    max_coast_speed: float = 2.5  # m/s
    # Physical bounds (ours). m/s: a person's top speed here (people walk at up to 1.6 m/s; a brisk
    # walk or a jog stays under it). No track's filter velocity exceeds it: the velocity is clamped
    # after every update and prediction, so that no hidden velocity carries a track, and a prediction
    # stays within this speed x the time since the track's last measurement of where it was measured.
    # None: unbounded (the paper)
    max_speed: float | None = 2.5
    # m: a matched detection whose centre lies farther from the track's last measured centre than
    # max_speed x the time since then, plus this, plus half the larger horizontal extent of the two
    # boxes (a box's centre moves by up to half its change of extent as more of the obstacle comes
    # into view), is no motion a person makes: the track is re-initialised there (its filter,
    # velocity, histories and labels start again, under a new id: what a consumer keeps by id
    # belonged to the obstacle it tracked before). None: never (the paper)
    jump_margin: float | None = 0.4
    # m: the camera's body around its position. A coasting track whose prediction would bring its
    # centre nearer the camera than this plus the track's half width (and nearer than it was) is held
    # where it was, its velocity toward the camera removed: nothing passes through the camera.
    # None: off
    camera_body_radius: float | None = 0.3
    # m: a coasting track whose prediction takes its centre nearer a wall of the geofence than this (a
    # person's radius), or beyond it, is held where it was across the wall, its velocity into the wall
    # removed: nothing walks through walls (DODT.set_scene gives the geofence; without one, off). None: off
    wall_clearance: float | None = 0.2
    # m: a track left without a detection whose centre lies this close to the centre of a track a detection
    # updated in the same frame is the same obstacle twice (one of a person's two tracks, which take the
    # person's boxes in turn): it is dropped instead of coasting on (ours). None: off
    duplicate_radius: float | None = 0.25
    output_history: float = 3.0  # s of centre history kept and output (the paper's figures show 3 s)
    # output size: exponential smoothing weight of the new detection, per frame at reference_rate (ours)
    size_smoothing: float = 0.3


@dataclass(frozen=True)
class IdentificationConfig:
    method: str = "voting"  # voting (paper), velocity (velocity threshold only, baselines)
    # s: vote against the cloud this long back (the newest at least this old), ref frame_skip k = 5
    # frames at 30 Hz
    vote_span: float = 5 / 30
    velocity_threshold: float = 0.15  # m/s, T_vel on the filtered speed, ref dynamic_velocity_threshold
    vote_velocity: float = 0.15  # m/s, T_vote per point, ref
    vote_ratio: float = 0.8  # T_ratio, ref dynamic_voting_threshold
    max_skip_ratio: float = 0.5  # ref maximum_skip_ratio
    max_point_speed: float = 2.5  # m/s; farther nearest neighbours are no correspondence (ours)
    # ours: an obstacle with more points votes with an even sample of this many (0: all). The
    # ratio's standard error stays under 0.04; voting is then about 3x cheaper for walls and
    # shelves (a median of 635 points per vote on the drone's corridor frames)
    max_vote_points: int = 200
    # ours: an obstacle whose box is wider than this (horizontal diagonal, m) is no walking person
    # or pair of people: it is not voted on and is no candidate (0: all are voted on). Such boxes are
    # walls and shelves seen from a moving camera, whose votes cost time and never make a candidate
    max_vote_extent: float = 2.5
    range_margin: float = 0.2  # m; points this close to depth_max back then are not voted on (ours)
    # px; points that were this close to the image border back then are not voted on: the cloud
    # skips the border (depth margin 10 px), and an edge of the view cuts obstacles (ours)
    fov_margin_px: float = 15.0
    # candidate in every frame within this span to become dynamic: ref default 3 consecutive frames
    # (ours too; 2 / 30 s; at 10 Hz and below, where a frame interval is longer, the frame itself:
    # dodt.windows.FrameClock.frames_within). The authors' navigation configuration uses 5
    # (autonomous_flight cfg/dynamic_navigation); 3 reports a person coming into view 2 frames sooner,
    # and release_span below keeps a young dynamic track from blinking static
    consistency_span: float = 2 / 30  # s
    # ours: a dynamic track turns static only when no frame over this span was a candidate (3 frames
    # in a row at 30 Hz; None: at the first one, as the reference code does for a track younger than
    # the force-dynamic window, whose label then blinks with the vote)
    release_span: float | None = 2 / 30
    # a track dynamic in at least this fraction of its frames with a detection over this span (as many as
    # it holds at the measuring sensor's rate: 30 camera frames, 11 scans at 10 Hz) stays dynamic: ref
    # frames_force_dynamic 10 of frames_force_dynamic_check_range 30 at 30 Hz
    force_dynamic_span: float | None = 29 / 30  # s; None: no force-dynamic lock
    force_dynamic_fraction: float = 1 / 3
    constrain_size: bool = False  # ref constrain_size: dynamic only if about person-sized
    target_size: tuple[float, float, float] = (0.5, 0.5, 1.7)  # m, ref target_object_size
    target_size_tolerance: float = 0.5  # m


@dataclass(frozen=True)
class MotionConfig:
    """The motion label (dodt.motion_label, ours): which tracks the point voting leaves static are
    reported dynamic all the same, as tall boxes tracked at walking speed. Point voting is weakest for a
    person walking straight at the camera (the surface moves along the rays, so nearest-neighbour
    matches fall short of the vote threshold): such a person can be tracked at the right velocity yet
    labelled static. A track labelled dynamic once (by either route) stays so below ``min_speed``: a
    walker slowing down to turn or stop loses the vote and the speed, not the chance that it walks on.
    The label needs a static map (DODT.set_scene) to tell a static obstacle's edge from a person."""

    enabled: bool = True
    min_speed: float = 0.5  # m/s, filtered horizontal speed ...
    max_speed: float = 2.5  # m/s ... up to a run (faster: a box jumping between wall fragments)
    height: tuple[float, float] = (1.0, 2.3)  # m, box height of a standing person
    max_footprint: float = 1.2  # m, longest horizontal side: not a wall seen end-on
    min_age: float = 0.2  # s, a track this old at least
    # A measured box lying this much (share of its footprint) on structure the static map has held for a
    # second or more (DODT.set_scene; without a map the label is off) is a static obstacle's edge, not a
    # person: that track is never labelled dynamic by motion again
    on_structure: float = 0.2
    # m: a measured box whose centre lies this close to a side of the geofence (DODT.set_scene; the
    # corridor's walls), or beyond it, is a fragment of the wall, never labelled dynamic by motion again: no
    # person's centre comes closer to a wall than the person's radius
    wall_margin: float = 0.15
    # m: a box whose bottom is this close above the lowest height the camera sees at the box is taken to
    # be cut by the image's lower edge (dodt.motion_label.person_tall)
    bottom_edge_tolerance: float = 0.15

    def __post_init__(self):
        lo, hi = self.height
        if not 0.0 <= self.min_speed <= self.max_speed:
            raise ValueError(f"motion: need 0 <= min_speed <= max_speed, got {self.min_speed} and {self.max_speed}")
        if not 0.0 <= lo <= hi:
            raise ValueError(f"motion: height must be [low, high] with 0 <= low <= high, got {[lo, hi]}")
        if not self.max_footprint > 0.0:
            raise ValueError(f"motion: max_footprint must be > 0, got {self.max_footprint}")
        if not self.min_age >= 0.0 or not self.bottom_edge_tolerance >= 0.0 or not self.wall_margin >= 0.0:
            raise ValueError(f"motion: min_age, bottom_edge_tolerance and wall_margin must be >= 0, got "
                             f"{self.min_age}, {self.bottom_edge_tolerance} and {self.wall_margin}")
        if not 0.0 <= self.on_structure <= 1.0:
            raise ValueError(f"motion: on_structure is a share of the footprint, 0 to 1, got {self.on_structure}")


@dataclass(frozen=True)
class LearnedConfig:
    """The optional learned person detector, YOLO-MAD (paper Sec. III-B; ref sections 4-5).

    The model shipped in dodt/models is trained on this project's simulator renders only; on a
    real camera's images bring a detector trained on real ones (``model`` and ``layout``: an ONNX
    export of a COCO-trained YOLOv8 / YOLO11 / YOLOv5 / YOLOX, dodt.learned.yolo)."""

    enabled: bool = False
    # ONNX file ("" -> the model shipped in dodt/models). Ours has its .json record beside it; a
    # model of a YOLO layout needs none
    model: str = ""
    # the model's output layout: "auto" (ours, or a YOLO layout told by the output's shape), "dodt",
    # "yolov8" (Ultralytics YOLOv8 / YOLO11), "yolov5" (decoded in the graph: YOLOv5, YOLOv7), "yolox"
    layout: str = "auto"
    person_class: int = 0  # the person class of a multi-class YOLO model (COCO: 0)
    input_size: tuple[int, int] | None = None  # (width, height) for a model whose input size is not fixed
    # a YOLO model's input: colour order ("rgb" / "bgr"), pixel scale (1/255 or 1) and letterbox
    # ("center", "top-left", "none"); None: its layout's (dodt.learned.yolo.PREPROCESS)
    channels: str | None = None
    pixel_scale: float | None = None
    letterbox: str | None = None
    score_threshold: float | None = None  # None -> the value recorded with the model (0.3 without a record)
    nms_iou: float = 0.45  # ref
    # ours: Gaussian soft-NMS (dodt.learned.layout.soft_nms) with this sigma instead of NMS at
    # nms_iou (0). People walking close together, or one partly hidden behind another, have
    # boxes that overlap by more than 0.45, and NMS kept one of them; soft-NMS lowers the score of
    # an overlapping box instead of dropping it
    soft_nms_sigma: float = 0.5
    threads: int = 1  # onnxruntime intra-op threads
    # views of the image the network runs on, fused (dodt.learned.views; ours): ("full",) is the
    # plain detector; ("full", "flip", "center") also runs the mirrored image and an enlarged
    # central crop, at three times the inference time
    views: tuple[str, ...] = ("full",)
    mad_n: float = 1.5  # depths within median +- n MAD belong to the object, ref (the paper leaves n open)
    margin_px: int = 2  # px cut from each side of the 2D box before reading depths (ours)
    # the box's central part read for the depth (fractions of its width and height; ours): the torso
    core_x: tuple[float, float] = (0.3, 0.7)
    core_y: tuple[float, float] = (0.15, 0.6)
    # d~, the depth the MAD range is centred on: this percentile of the core's depths (50: the
    # paper's median; lower leans to the nearer surface, the person before the background)
    depth_percentile: float = 30.0
    min_depth_pixels: int = 20  # fewer valid depths in the box: no 3D box (ours)
    # ours (dodt.learned.lifting.lift_boxes): a person box overlapped by the box of a person in
    # front of him (its bottom edge lower and it taller, each by this fraction of his box's
    # height: nearer on the same floor; his box reaching past its side by this fraction of his
    # width, else it is a part of that person's box) reads no depth inside that box that is not
    # farther than the front person's depth range (+ occluder_depth_margin). The percentile d~
    # leans to the nearer surface, so read through the person in front, a half-hidden person was
    # lifted onto him; the stride-8 detector finds such people. A fraction of a box's height and
    # width; None: off
    occluder_margin: float | None = 0.1
    occluder_depth_margin: float = 0.3  # m
    # ours: a person as tall as this, showing as high as the 2D box, stands at most fy * height /
    # box height away, so depths farther than that are the background seen past the person and are
    # not read (a box cut by the image's edge or an occluder is shorter: the bound only loosens).
    # A far person is narrow and the depth camera leaves holes at depth edges, so the background
    # could hold most of the box's valid depths, and the box was lifted onto the background on the
    # person's bearing, metres behind him. None: no bound
    max_person_height: float | None = 2.0  # m
    # ours: a box whose depth d~ is farther than this is dropped. The camera reports nothing beyond
    # its range (10 m), so near it the far half of a person's noisy depths is missing and the
    # rest leans toward the camera (a person standing at 9.8 m lifted 0.5-0.7 m in front). None: none
    max_lift_range: float | None = 9.0  # m
    depth_min: float = 0.2  # m, valid depths for lifting
    depth_max: float = 10.0  # m: beyond the ensemble's 5 m, the module's range extension
    min_thickness: float = 0.3  # m: the 3D box is at least this deep (ours)
    center_behind_median: float = 0.1  # m: box centre behind the median depth of the visible surface (ours)
    person_size: tuple[float, float, float] = (0.5, 0.5, 1.8)  # m, ref humanSize for the size sanity rule
    overwrite_distance: float = 3.0  # m, ref yolo_overwrite_distance: closer unmatched boxes are dropped
    iou_threshold: float = 0.05  # mutual best match with a fused box, ref
    # what a mutual best match becomes: "fused" (ours: the geometric box, measured from depth,
    # marked a person) or "union" (ref: the union of the two boxes)
    match_box: str = "fused"
    # an unmatched learned box this close (m, horizontally) to a fused box is taken for a second,
    # misplaced view of it and dropped (ours; the ref adds it as a new obstacle)
    duplicate_gate: float = 0.6
    # ours: a mutual best match marks the fused box a person only when the two boxes' centres lie
    # within this (m, horizontally; 0: always). A person close to a wall or an obstacle lifts to
    # his own depth, while the fused box his 2D box best overlaps can be the structure 0.7-1 m
    # behind him, which the person label then made a dynamic track (a false report of the wall)
    person_match_gate: float = 0.5
    # ours: a mutual best match does not mark a fused box taller than this (m) a person. People here
    # are at most 1.85 m tall; a taller box is an obstacle, which a 2D box cut by the image's side
    # edge matches when its torso region reads the obstacle behind the person (a tall obstacle
    # behind a person walking out of view then became a dynamic report for a few frames). 0: no bound
    person_box_max_height: float = 2.5
    # ours: where the fused box of a mutual best match is lower than this fraction of the learned
    # box, it is a fragment of the person (the part within the depth range, or the part in view),
    # and the union of the two boxes replaces it; otherwise the fused box stays (match_box). A
    # track fed by the person's lifted box then saw a fragment a metre lower, which association
    # refused, and a second track started on the person: ID switches at the 5 m edge of the depth
    # range. 0: off
    fragment_height: float = 0.6
    # a track is a person when this fraction of its detections over person_span were person boxes
    # (ours; the ref uses the latest box alone). All over 2 / 30 s (3 of 3 frames at 30 Hz; 2 frames
    # at a lower rate): a track is labelled at its third frame
    # (67 ms after its first), not its second; a young track's velocity is its worst and a box
    # lifted once from a far person's noisy depth can lie a metre off him
    person_span: float = 2 / 30  # s
    person_fraction: float = 1.0
    # ours: a person box whose 3D box crosses the image's left or right edge casts no vote, either
    # way (dodt.geometry.box_cut_by_view_side): lifted from the part of the person in view, it lies
    # off him, and the part's centre slides along the edge as he walks in or out of view, so a
    # track labelled on such boxes reported a velocity made of that slide. A person track keeps its
    # label while its boxes are cut. True: every person box votes
    cut_boxes_vote: bool = False
    # a person track beyond the ensemble's depth range (depth.depth_max from the camera), where the
    # learned boxes are its only detections, coasts at most this long (ours; 0: as any track, for
    # track.coast_time). Such a track's velocity comes from boxes lifted from noisy far depth, and
    # coasting on it drifts off its person and reports someone who is not there. A shorter coast
    # loses more of the far people instead
    far_coast_time: float = 0.4  # s
    # ours: a coasting person track is dropped this long after its last detection (0: never) when its
    # image box lies in full view, nothing nearer hides it (less than unseen_occluder_fraction of
    # the box's valid depths lie in front of it) and no 2D person box of the frame overlaps its
    # image box by unseen_iou: the detector looks right at its place and sees no person there.
    # Such tracks were most of dodt+yolo's false and duplicate reports: coasting on a last velocity
    # that had drifted 0.5-1.5 m off their person, who was tracked again by another track or not
    # detected at all
    unseen_after: float = 6 / 30  # s: 6 missed frames at 30 Hz
    unseen_iou: float = 0.5
    unseen_occluder_fraction: float = 0.3


@dataclass(frozen=True)
class LidarDetectorConfig:
    """The LiDAR detector of a rig with a LiDAR (dodt.lidar_detector; ours, after LV-DOT)."""
    max_range: float = 6.0  # m horizontally: farther returns are too sparse to cluster
    min_range: float = 0.35  # m from the sensor: nearer returns are the vehicle's own frame
    wall_margin: float = 0.15  # m inside the geofence's y sides: the corridor's walls
    voxel: float = 0.1  # m, the voxel filter's cell
    eps: float = 0.35  # m, DBSCAN's radius on the filtered points
    min_points: int = 4  # DBSCAN's core points' neighbours (the point included)
    max_footprint: float = 2.0  # m: a wider cluster is structure
    structure_fraction: float = 0.5  # of a box on established static voxels: structure
    floor_tolerance: float = 0.15  # m above the lowest ray's reach: the box reaches the floor
    # identification of a track a LiDAR box updated (dodt.tracker): point voting against the union of the
    # clouds of the vote_scans newest scans at least vote_span old, a point voting dynamic above
    # vote_velocity. One scan's lines leave gaps of up to a few degrees (15-30 cm at 5 m); three scans
    # fill them to a few centimetres (6-8 cm at 5-6 m, 90th percentile), which over vote_span reads as
    # under half of vote_velocity, while the points of a walker's side that faces the sensor move
    # 0.25 m or more, beyond the part of its own earlier place they still overlap
    vote_span: float = 0.5  # s
    vote_scans: int = 3
    vote_velocity: float = 0.25  # m/s
    # ours: a point whose surface (its normal from its nearest points, turned towards the sensor now) faced
    # away from every scan voted against, by more than this cosine, was not seen then: it does not vote.
    # A static obstacle the sensor passes shows new faces, whose points find the old faces' within reach
    # and would vote moving. None: every point votes
    face_cos: float | None = -0.1
    # ours: a point votes only if it lay this far inside the field of the scans voted against (above
    # their lowest ray; dodt.identification.in_lidar_field), and a frame votes only when
    # at least min_field_share of its points did (otherwise its label stays): what the sensor passed
    # close by was under its lowest ray, and comes into its field as it moves away. A walker beside the
    # sensor keeps its upper body in the field while its legs come into it: the share keeps its vote,
    # the margin its legs out of it. None: every point votes
    field_margin: float | None = 0.1  # m
    min_field_share: float = 0.5


@dataclass(frozen=True)
class DODTConfig:
    name: str = "dodt"
    depth: DepthConfig = field(default_factory=DepthConfig)
    voxel: VoxelConfig = field(default_factory=VoxelConfig)
    udepth: UDepthConfig = field(default_factory=UDepthConfig)
    dbscan: DBSCANConfig = field(default_factory=DBSCANConfig)
    ensemble: EnsembleConfig = field(default_factory=EnsembleConfig)
    association: AssociationConfig = field(default_factory=AssociationConfig)
    kalman: KalmanConfig = field(default_factory=KalmanConfig)
    track: TrackConfig = field(default_factory=TrackConfig)
    identification: IdentificationConfig = field(default_factory=IdentificationConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    learned: LearnedConfig = field(default_factory=LearnedConfig)
    lidar: LidarDetectorConfig = field(default_factory=LidarDetectorConfig)
    # Hz: the frame rate the per-frame constants (KalmanConfig's Q, TrackConfig.size_smoothing) are
    # given for, the reference code's 30 Hz timers; at another rate they are scaled by dt x this
    reference_rate: float = 30.0


def override(cfg: DODTConfig, assignments) -> DODTConfig:
    """``cfg`` with ``section.field=value`` assignments applied (``name=value`` for a top-level
    field), each value read as the field's type: a number, true / false, a comma list for a tuple,
    none for an optional field. A ValueError names the assignment and what is wrong."""
    import dataclasses
    import typing

    for text in assignments:
        key, sep, raw = str(text).partition("=")
        key, raw = key.strip(), raw.strip()
        if not sep or not key:
            raise ValueError(f"--set {text!r}: expected section.field=value, e.g. kalman.q_pos=0.02")
        path = key.split(".")
        if len(path) > 2:
            raise ValueError(f"--set {key}: expected section.field or a top-level field")
        owner = cfg if len(path) == 1 else getattr(cfg, path[0], None)
        if not dataclasses.is_dataclass(owner) or (len(path) == 2 and path[0] not in {f.name for f in dataclasses.fields(cfg)}):
            sections = ", ".join(f.name for f in dataclasses.fields(cfg) if dataclasses.is_dataclass(getattr(cfg, f.name)))
            raise ValueError(f"--set {key}: no section {path[0]!r}; sections: {sections}")
        name = path[-1]
        hints = typing.get_type_hints(type(owner))
        if name not in hints or dataclasses.is_dataclass(getattr(owner, name)):
            raise ValueError(f"--set {key}: {type(owner).__name__} has no field {name!r}")
        try:
            value = _parse_value(raw, hints[name])
        except ValueError as e:
            raise ValueError(f"--set {key}={raw}: {e}") from None
        new = dataclasses.replace(owner, **{name: value})
        cfg = new if len(path) == 1 else dataclasses.replace(cfg, **{path[0]: new})
    return cfg


def _parse_value(raw: str, hint):
    import typing

    args = typing.get_args(hint)
    optional = type(None) in args
    if raw.lower() in ("none", "null") and optional:
        return None
    if optional:
        hint = next(a for a in args if a is not type(None))
        args = typing.get_args(hint)
    origin = typing.get_origin(hint)
    if origin is tuple:
        parts = [p.strip() for p in raw.split(",") if p.strip()]
        item = args[0] if args else str
        if len(args) > 1 and args[-1] is not Ellipsis and len(parts) != len(args):
            raise ValueError(f"expected {len(args)} comma-separated values")
        return tuple(_parse_value(p, item) for p in parts)
    if hint is bool:
        if raw.lower() in ("true", "1", "yes", "on"):
            return True
        if raw.lower() in ("false", "0", "no", "off"):
            return False
        raise ValueError("expected true or false")
    if hint is int:
        try:
            return int(raw)
        except ValueError:
            raise ValueError("expected a whole number") from None
    if hint is float:
        try:
            return float(raw)
        except ValueError:
            raise ValueError("expected a number") from None
    return raw  # a string
