"""The one place that wires components: configuration sections, perception modes and DODT presets, and
planners, built-in or plug-in.

- **Sections** (experiments.config is generic; this names them): ``episode`` (EpisodeConfig), ``shield``
  and ``navigator`` (the default planner's), ``map`` (the static map's, after the episode sizes it to the
  scenario), ``dodt`` (on top of a DODT mode's preset), ``oracle`` (the
  oracle modes', on top of each mode's own), and ``planner`` / ``perception`` for a plug-in class that
  declares a configuration dataclass as its ``config_class`` (built then as ``Class(config)``).
  Values are checked against experiments.config_limits for the built-in sections and against a plug-in
  field's ``metadata["range"]``.
- **Perception**: a mode name (``MODES``), a DODT preset (dodt.presets), or a plug-in's ``module:Class``.
- **Planners**: ``default`` (the maneuver and MPC planner behind the passive-safety shield, the MPC an OSQP
  QP), ``nmpc`` (the same with the CasADi NMPC, planner.mpc.nmpc) or a plug-in's ``module:Class``, which
  ``shield=True`` puts behind the same shield.
"""
from __future__ import annotations

from typing import Any

from dodt.presets import PRESETS, preset
from experiments import config_limits
from dodt.config import DODTConfig
from experiments.config import Settings, build
from experiments.episode_config import EpisodeConfig
from experiments.perception_modes import (MODES, NOISY_ORACLE_VELOCITY_NOISE, DODTPerception,
                                          OracleConfig, OraclePerception, StaticOnlyPerception)
from experiments.plugins import PluginError, config_class, is_spec, load_plugin
from planner.map.voxel_map import MapConfig
from planner.mpc.config import MPCConfig
from planner.nominal.navigator import MPCPlanner, NavigatorConfig
from planner.shield.shield import PassiveSafetyShield, ShieldConfig

DEFAULT_PLANNER = "default"
DEFAULT_PLANNER_LABEL = "PassiveSafetyShield"  # what summaries record for the default planner
# the built-in planners: the maneuver layer and an MPC behind the shield; by name, the MPC's solver and what
# summaries record
BUILTIN_PLANNERS = {DEFAULT_PLANNER: ("osqp", DEFAULT_PLANNER_LABEL), "nmpc": ("nmpc", "PassiveSafetyShield+NMPC")}
PLANNER_METHODS = ("reset", "plan")
PERCEPTION_METHODS = ("reset", "update")
PLUGIN_SECTIONS = ("planner", "perception")


# The map an override is checked against: an episode sizes its map to the scenario's corridor (this is the
# shipped corridor's), then applies the map section
CHECKED_MAP = MapConfig(origin=(-0.5, -2.5, -0.1), size=(17.0, 5.0, 3.2))


def builtin_sections() -> dict[str, Any]:
    """The built-in sections and their default configurations (the dodt section's: the dodt preset)."""
    return {"episode": EpisodeConfig(), "shield": ShieldConfig(), "navigator": NavigatorConfig(),
            "map": CHECKED_MAP, "dodt": preset("dodt"), "oracle": OracleConfig()}


def known_modes() -> tuple[str, ...]:
    """Every built-in perception name: the modes and the DODT presets, once each."""
    return tuple(dict.fromkeys(MODES + tuple(PRESETS)))


def _check(key: str, value) -> None:
    """The range check of a built-in section's key (plug-in sections carry their own)."""
    if key.split(".", 1)[0] not in PLUGIN_SECTIONS:
        config_limits.check_value(key, value)


def sections_for(perception: str = "dodt", planner: str = DEFAULT_PLANNER) -> dict[str, Any]:
    """The sections a run with these components accepts: the built-in ones, and ``planner`` /
    ``perception`` for a plug-in that declares a configuration class."""
    out = builtin_sections()
    for name, spec in (("planner", planner), ("perception", perception)):
        if is_spec(spec):
            cls = config_class(spec)
            if cls is not None:
                out[name] = cls()
    return out


def settings_for(config_file=None, sets=(), perception: str = "dodt", planner: str = DEFAULT_PLANNER) -> Settings:
    """Settings from ``--config`` and ``--set``, every key and value checked now (ConfigError; PluginError
    for a plug-in spec that does not load)."""
    sections = sections_for(perception, planner)
    # sections that moved: where their keys live now
    absent = {"moving_rule": "the moving-track rule is DODT's motion label now: set dodt.motion.<field>"}
    for name, spec in (("planner", planner), ("perception", perception)):
        if name not in sections:
            who = f"the {name} plug-in {spec}" if is_spec(spec) else f"the built-in {name} {spec!r}"
            absent[name] = f"{who} declares no configuration of its own (a plug-in's config_class)"
    return build(sections, config_file, sets, _check, absent)


def plugin_sections(perception, planner, settings: Settings) -> dict:
    """The configurations of the plug-ins among ``perception`` and ``planner`` (specs; objects have
    none) that declare one, by section, as they are built with ``settings``."""
    out = {}
    for name, spec in (("planner", planner), ("perception", perception)):
        cfg = _plugin_config(spec, name, settings)
        if cfg is not None:
            out[name] = cfg
    return out


def configured(settings: Settings, section: str, default):
    """``default`` with ``settings``' overrides of ``section`` applied and checked."""
    return settings.apply(section, default, _check)


def _plugin_config(spec, section: str, settings: Settings):
    """The configuration a plug-in spec declares (``config_class``), with ``section``'s overrides; None for
    a built-in name, an object, or a plug-in that declares none."""
    cls = config_class(spec) if isinstance(spec, str) and is_spec(spec) else None
    return None if cls is None else configured(settings, section, cls())


# --------------------------------------------------------------------------- perception


def check_perception(spec: str) -> None:
    """Raises PluginError when ``spec`` is neither a built-in name nor a usable plug-in."""
    if is_spec(spec):
        load_plugin(spec, PERCEPTION_METHODS, "perception", "dodt.protocol.PerceptionModule")
    elif spec not in known_modes():
        raise PluginError(f"unknown mode {spec!r}; known: {', '.join(known_modes())}; or module:Class")


def make_perception(spec: str, settings: Settings = Settings(), learned_detector=None):
    """A perception module by name or ``module:Class``, each section of ``settings`` on top of the mode's
    own configuration: ``dodt`` for the DODT modes, ``oracle`` for the oracle modes,
    ``perception`` for a plug-in with a configuration class; static-only reads none."""
    if is_spec(spec):
        return load_plugin(spec, PERCEPTION_METHODS, "perception", "dodt.protocol.PerceptionModule",
                           _plugin_config(spec, "perception", settings))
    if spec in ("oracle", "oracle-360", "oracle-noisy"):
        own = OracleConfig(velocity_noise=NOISY_ORACLE_VELOCITY_NOISE) if spec == "oracle-noisy" else OracleConfig()
        return OraclePerception(configured(settings, "oracle", own), all_around=spec == "oracle-360", name=spec)
    if spec == "static-only":
        return StaticOnlyPerception()
    if spec in PRESETS:
        return DODTPerception(spec, learned_detector=learned_detector, config=configured(settings, "dodt", preset(spec)))
    raise PluginError(f"unknown perception mode {spec!r}; known: {', '.join(known_modes())}")


def perception_sections(perception) -> dict:
    """The configuration a perception module runs with, by section: ``dodt`` for a module holding a DODT,
    ``oracle`` for the oracle modes (a plug-in's own: plugin_sections)."""
    out = {}
    cfg = getattr(getattr(perception, "dodt", None), "cfg", None)
    if isinstance(cfg, DODTConfig):
        out["dodt"] = cfg
    if isinstance(perception, OraclePerception):
        out["oracle"] = perception.cfg
    return out


# --------------------------------------------------------------------------- planners


def check_planner(spec: str) -> None:
    """Raises PluginError when ``spec`` names no planner (a plug-in is loaded and built once)."""
    if spec not in BUILTIN_PLANNERS:
        if not is_spec(spec):
            raise PluginError(f"unknown planner {spec!r}; built-in: {', '.join(BUILTIN_PLANNERS)}; or module:Class")
        load_plugin(spec, PLANNER_METHODS, "planner", "planner.types.Planner")


def planner_label(spec: str | None, shield: bool = False) -> str:
    """What a summary records as ``planner`` for a spec (None: the default planner); ``shield+spec`` for a
    plug-in flown behind the shield."""
    if spec is None:
        return DEFAULT_PLANNER_LABEL
    if spec in BUILTIN_PLANNERS:
        return BUILTIN_PLANNERS[spec][1]
    return f"shield+{spec}" if shield else spec


def make_planner(spec: str, robot_radius: float, settings: Settings = Settings(), shield: bool = False):
    """The planner for an episode of a vehicle of horizontal radius ``robot_radius``: a built-in one (the
    maneuver and MPC planner behind the shield, ``navigator`` and ``shield`` sections applied; BUILTIN_PLANNERS)
    or a plug-in (its ``planner`` section applied), behind the shield too when ``shield``."""
    if spec in BUILTIN_PLANNERS:
        nav = configured(settings, "navigator", NavigatorConfig(mpc=MPCConfig(robot_radius=robot_radius)))
        return behind_shield(MPCPlanner(nav, solver=BUILTIN_PLANNERS[spec][0]), robot_radius, settings)
    plugin = load_plugin(spec, PLANNER_METHODS, "planner", "planner.types.Planner",
                         _plugin_config(spec, "planner", settings))
    return behind_shield(plugin, robot_radius, settings) if shield else plugin


def behind_shield(planner, robot_radius: float, settings: Settings = Settings()) -> PassiveSafetyShield:
    """``planner`` behind the passive-safety shield (its ``shield`` section applied): the shield flies the
    planner's trajectory only while it keeps a safe stop, and brakes or holds otherwise."""
    return PassiveSafetyShield(planner, configured(settings, "shield", ShieldConfig(drone_radius=robot_radius)))


def planner_sections(planner) -> dict:
    """The configuration a planner runs with, by section: ``shield`` and ``navigator`` (a plug-in's own:
    plugin_sections)."""
    out = {}
    if isinstance(planner, PassiveSafetyShield):
        out["shield"] = planner.cfg
        if isinstance(planner.planner, MPCPlanner):
            out["navigator"] = planner.planner.cfg
    return out
