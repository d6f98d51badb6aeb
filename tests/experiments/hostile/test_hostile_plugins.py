"""Hostile plug-ins: a planner or perception module whose file does not import, exits, interrupts, is not a
class, lacks the protocol's methods, or declares a broken configuration is refused in one line before any
work; one whose reset, plan or update raises, exits or returns garbage is contained at the boundary
(experiments.guards): the run goes on, the failure is counted, and the command exits non-zero.

The load-time cases run each command in this process; the boundary cases call the guards directly with
the plug-in's output (cheap); a few end-to-end episodes are marked slow.
"""
from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from hostile_cli import assert_refused, cli, no_work  # noqa: F401 - no_work is a fixture

from dodt.protocol import PerceptionOutput, TrackReport
from experiments.guards import PerceptionGuard, PlannerGuard
from planner.types import ObstaclePrediction, PlannerInput, Trajectory

PLANNER_BODY = """
class P:
    def reset(self, context=None):
        pass
    def plan(self, inp):
        return None
"""
PERCEPTION_BODY = """
class P:
    def reset(self, context=None):
        pass
    def update(self, frame, truth):
        return None
"""

# (id, the file's text (or bytes), what the one line names). {body} is the protocol's class for the role.
LOAD_CASES: list[tuple[str, str | bytes, str]] = [
    ("syntax error", "class P(:\n", "SyntaxError"),
    ("import error", "import no_such_module_anywhere\n{body}", "ModuleNotFoundError"),
    ("raises at import", "raise RuntimeError('boom at import')\n", "boom at import"),
    ("sys.exit(0) at import", "import sys\nsys.exit(0)\n", "SystemExit"),
    ("sys.exit(3) at import", "import sys\nsys.exit(3)\n", "SystemExit"),
    ("sys.exit text at import", "import sys\nsys.exit('bye')\n", "SystemExit"),
    ("os._exit-free BaseException", "class Escape(BaseException):\n    pass\nraise Escape('out')\n", "Escape"),
    ("GeneratorExit at import", "raise GeneratorExit\n", "GeneratorExit"),
    ("recursion at import", "def f():\n    return f()\nf()\n", "RecursionError"),
    ("memory error at import", "raise MemoryError\n", "MemoryError"),
    ("no class", "X = 1\n", "no class"),
    ("not a class", "P = 5\n", "not a class"),
    ("a function", "def P():\n    return None\n", "not a class"),
    ("no methods", "class P:\n    pass\n", "protocol"),
    ("methods not callable", "class P:\n    reset = 1\n    plan = 2\n    update = 3\n", "protocol"),
    ("init raises", "class P:\n    def __init__(self):\n        raise ValueError('no')\n", "ValueError"),
    ("init exits", "import sys\nclass P:\n    def __init__(self):\n        sys.exit(0)\n", "SystemExit"),
    ("init needs arguments", "class P:\n    def __init__(self, a, b):\n        pass\n", "TypeError"),
    ("getattr raises", "class P:\n    def __getattr__(self, name):\n        raise RuntimeError(name)\n",
     "protocol"),
    ("module getattr raises", "def __getattr__(name):\n    raise RuntimeError(name)\n", "P"),
    ("config not a dataclass", "{body}\nP.config_class = int\n", "dataclass"),
    ("config instance", "from dataclasses import dataclass\n@dataclass\nclass C:\n    x: int = 1\n{body}\n"
                        "P.config_class = C()\n", "dataclass"),
    ("config without defaults", "from dataclasses import dataclass\n@dataclass\nclass C:\n    x: int\n{body}\n"
                                "P.config_class = C\n", "C()"),
    ("config post_init raises", "from dataclasses import dataclass\n@dataclass\nclass C:\n    x: int = 1\n"
                                "    def __post_init__(self):\n        raise ValueError('bad default')\n{body}\n"
                                "P.config_class = C\n", "bad default"),
    ("config post_init exits", "import sys\nfrom dataclasses import dataclass\n@dataclass\nclass C:\n"
                               "    x: int = 1\n    def __post_init__(self):\n        sys.exit(0)\n{body}\n"
                               "P.config_class = C\n", "SystemExit"),
    ("init rejects config", "from dataclasses import dataclass\n@dataclass\nclass C:\n    x: int = 1\n"
                            "class P:\n    config_class = C\n    def __init__(self):\n        pass\n", "TypeError"),
    ("not UTF-8", "X = 'caf\u00e9'\n".encode("latin-1") + b"{body}", "SyntaxError"),
    ("binary", bytes(range(256)) * 4, "Error"),
    ("NUL bytes", b"\x00\x00\x00", "Error"),
    ("empty file", "", "no class"),
]


def _write(tmp: Path, data: str | bytes, body: str) -> Path:
    path = tmp / "plug.py"
    if isinstance(data, bytes):
        path.write_bytes(data.replace(b"{body}", body.encode()))
    else:
        path.write_text(data.replace("{body}", body))
    return path


def _load_ids():
    """(case, role, command): each case in each role by two commands; the two roles together take all four."""
    cmds = ("run", "sweep", "benchmark", "reproduce")
    return [(c, role, cmds[(c + r + k) % len(cmds)]) for c in range(len(LOAD_CASES))
            for r, role in enumerate(("planner", "perception")) for k in (0, 2)]


LOAD_IDS = _load_ids()


def _command(cmd: str, role: str, spec: str, out: str) -> list[str]:
    base = {"run": ["run", "corridor", "--out", out], "sweep": ["sweep", "corridor", "--out", out, "--seeds", "0:2",
                                                               "--jobs", "1", "--quiet"],
            "benchmark": ["benchmark", "nav", "--out", out, "--quick", "--quiet"],
            "reproduce": ["reproduce", "--out", out, "--quick"]}[cmd]
    return base + [f"--{role}", spec]


@pytest.mark.parametrize("case", LOAD_IDS, ids=[f"{LOAD_CASES[c][0]}-{r}-{m}" for c, r, m in LOAD_IDS])
def test_a_plugin_that_cannot_be_loaded_is_one_line(case, tmp_path, capsys, no_work, monkeypatch):
    c, role, cmd = case
    _, data, name = LOAD_CASES[c]
    path = _write(tmp_path, data, PLANNER_BODY if role == "planner" else PERCEPTION_BODY)
    monkeypatch.setattr(sys, "modules", dict(sys.modules))  # the plug-in's module is forgotten after the test
    code, err, _ = cli(_command(cmd, role, f"{path}:P", str(tmp_path / "out")), capsys)
    assert_refused(code, err, f"--{role}", name, status=2)
    assert not (tmp_path / "out").exists()


SPEC_CASES = ["nowhere.py:P", "no_such_module_xyz:P", ":P", "plug.py:", "plug.py:P:Q", "plug.py:P.Inner",
              "plug.py:__class__", "os:path", "math:pi", "builtins:int", "sys:exit", "plug.py:" + "P" * 5000,
              "/dev/null:P", "/:P", ".py:P", "TMP:P"]


@pytest.mark.parametrize("spec", SPEC_CASES)
@pytest.mark.parametrize("role", ["planner", "perception"])
def test_a_spec_that_names_no_usable_class_is_one_line(spec, role, tmp_path, capsys, no_work, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "plug.py").write_text(PLANNER_BODY if role == "planner" else PERCEPTION_BODY)
    spec = spec.replace("TMP", str(tmp_path))
    code, err, _ = cli(_command("run", role, spec, str(tmp_path / "out")), capsys)
    assert_refused(code, err, f"--{role}", status=2)
    assert not (tmp_path / "out").exists()


# --------------------------------------------------------------------------- the boundary, called directly


def _inp() -> PlannerInput:
    z = np.zeros(3)
    return PlannerInput(stamp=1.0, position=np.array([1.0, 0.0, 1.2]), velocity=np.array([0.5, 0.0, 0.0]),
                        acceleration=z, goal=np.array([9.0, 0.0, 1.2]), obstacles=())


def _traj(**kw) -> Trajectory:
    n = kw.pop("n", 5)
    base = dict(t0=1.0, dt=0.1, positions=np.zeros((n + 1, 3)), velocities=np.zeros((n + 1, 3)),
                accelerations=np.zeros((n, 3)))
    base.update(kw)
    return Trajectory(**base)


class Escape(BaseException):
    pass


def _raise(e):
    def f(*args, **kwargs):
        raise e
    return f


PLANS = {
    "None": lambda: None, "dict": lambda: {"t0": 0.0}, "string": lambda: "trajectory", "int": lambda: 5,
    "list": lambda: [[0.0, 0.0, 0.0]], "class": lambda: Trajectory, "empty": lambda: _traj(n=0),
    "dt nan": lambda: _traj(dt=math.nan), "dt 0": lambda: _traj(dt=0.0), "dt -1": lambda: _traj(dt=-0.1),
    "dt inf": lambda: _traj(dt=math.inf), "dt string": lambda: _traj(dt="0.1"), "dt bool": lambda: _traj(dt=True),
    "t0 nan": lambda: _traj(t0=math.nan), "t0 huge int": lambda: _traj(t0=10 ** 400), "t0 None": lambda: _traj(t0=None),
    "acc 2 columns": lambda: _traj(accelerations=np.zeros((5, 2))),
    "acc 1d": lambda: _traj(accelerations=np.zeros(15)), "acc nan": lambda: _traj(accelerations=np.full((5, 3), np.nan)),
    "acc strings": lambda: _traj(accelerations=[["a", "b", "c"]] * 5), "acc object": lambda: _traj(accelerations=object()),
    "acc ragged": lambda: _traj(accelerations=[[0, 0, 0], [0, 0]]), "acc huge ints": lambda: _traj(
        accelerations=[[10 ** 400, 0, 0]] * 5),
    "positions short": lambda: _traj(positions=np.zeros((3, 3))), "velocities inf": lambda: _traj(
        velocities=np.full((6, 3), np.inf)), "positions None": lambda: _traj(positions=None),
    "yaw string": lambda: _traj(yaw="north"), "yaw nan": lambda: _traj(yaw=math.nan), "yaw list": lambda: _traj(yaw=[0.0]),
    "status int": lambda: _traj(status=5), "solve_ms nan": lambda: _traj(solve_ms=math.nan),
    "runaway": lambda: _traj(n=200_000),
    "raises": _raise(RuntimeError("plan failed")), "zero division": lambda: 1 / 0,
    "sys.exit 0": _raise(SystemExit(0)), "sys.exit 1": _raise(SystemExit(1)), "escape": _raise(Escape("out")),
    "generator exit": _raise(GeneratorExit()), "recursion": _raise(RecursionError()), "memory": _raise(MemoryError()),
}


class _Planner:
    def __init__(self, plan):
        self._plan = plan

    def reset(self, context=None):
        pass

    def plan(self, inp):
        return self._plan()


@pytest.mark.parametrize("name", list(PLANS))
def test_a_planner_output_that_is_not_a_trajectory_becomes_a_counted_brake(name, capsys):
    guard = PlannerGuard(_Planner(PLANS[name]), "plug")
    for _ in range(3):
        traj = guard.plan(_inp())
        assert isinstance(traj, Trajectory) and traj.status.startswith("error:")
        assert np.all(np.isfinite(traj.accelerations)) and len(traj.accelerations) >= 1
    assert guard.errors.count == 3
    err = capsys.readouterr().err
    assert err.count("failed at t =") == 1  # shown once, later failures counted


@pytest.mark.parametrize("name", ["raises", "sys.exit 0", "escape", "generator exit"])
def test_a_planner_whose_reset_fails_is_counted(name, capsys):
    p = _Planner(lambda: None)
    p.reset = PLANS[name]
    guard = PlannerGuard(p, "plug")
    guard.reset(None)
    assert guard.errors.count == 1


def test_a_keyboard_interrupt_from_a_plugin_goes_through():
    with pytest.raises(KeyboardInterrupt):
        PlannerGuard(_Planner(_raise(KeyboardInterrupt())), "plug").plan(_inp())


def _obstacle(**kw) -> ObstaclePrediction:
    base = dict(id=1, center=np.array([3.0, 0.0, 0.9]), size=np.array([0.5, 0.5, 1.8]))
    base.update(kw)
    return ObstaclePrediction(**base)


def _track(**kw) -> TrackReport:
    base = dict(id=1, center=np.zeros(3), size=np.ones(3), velocity=np.zeros(3), dynamic=True)
    base.update(kw)
    return TrackReport(**base)


def _out(**kw) -> PerceptionOutput:
    base = dict(stamp=1.0, obstacles=())
    base.update(kw)
    return PerceptionOutput(**base)


UPDATES = {
    "None": lambda: None, "dict": lambda: {"stamp": 1.0}, "string": lambda: "out", "tuple": lambda: (1.0, ()),
    "stamp nan": lambda: _out(stamp=math.nan), "stamp string": lambda: _out(stamp="1"),
    "stamp huge": lambda: _out(stamp=10 ** 400), "obstacles None": lambda: _out(obstacles=None),
    "obstacles dict": lambda: _out(obstacles={1: 2}), "obstacles strings": lambda: _out(obstacles=("a", "b")),
    "obstacle dict": lambda: _out(obstacles=({"id": 1},)),
    "center 2": lambda: _out(obstacles=(_obstacle(center=np.zeros(2)),)),
    "center nan": lambda: _out(obstacles=(_obstacle(center=np.array([np.nan, 0, 0])),)),
    "size string": lambda: _out(obstacles=(_obstacle(size="big"),)),
    "velocity inf": lambda: _out(obstacles=(_obstacle(velocity=np.array([np.inf, 0, 0])),)),
    "std nan": lambda: _out(obstacles=(_obstacle(position_std=math.nan),)),
    "max_speed None": lambda: _out(obstacles=(_obstacle(max_speed=None),)),
    "id string": lambda: _out(obstacles=(_obstacle(id="one"),)), "id nan": lambda: _out(obstacles=(_obstacle(id=math.nan),)),
    "id huge": lambda: _out(obstacles=(_obstacle(id=10 ** 30),)),
    "too many": lambda: _out(obstacles=tuple(_obstacle(id=i) for i in range(10_001))),
    "clear box 1": lambda: _out(clear_boxes=((np.zeros(3),),)), "clear box nan": lambda: _out(
        clear_boxes=((np.full(3, np.nan), np.ones(3)),)), "clear boxes None": lambda: _out(clear_boxes=None),
    "tracks None": lambda: _out(tracks=None), "track string": lambda: _out(tracks=("t",)),
    "track dict empty": lambda: _out(tracks=({},)), "track dict nan": lambda: _out(
        tracks=({"id": 1, "center": [math.nan, 0, 0], "size": [1, 1, 1], "dynamic": True},)),
    "track dict id string": lambda: _out(tracks=({"id": "x", "center": [0, 0, 0], "size": [1, 1, 1], "dynamic": True},)),
    "track dict huge": lambda: _out(tracks=({"id": 1, "center": [10 ** 400, 0, 0], "size": [1, 1, 1], "dynamic": 1},)),
    "track dict age nan": lambda: _out(tracks=({"id": 1, "center": [0, 0, 0], "size": [1, 1, 1], "dynamic": True,
                                                "age": "nan"},)),
    "track center object": lambda: _out(tracks=(_track(center=object()),)),
    "track size 2": lambda: _out(tracks=(_track(size=np.ones(2)),)),
    "track id float": lambda: _out(tracks=(_track(id=1.5),)), "track id None": lambda: _out(tracks=(_track(id=None),)),
    "track dynamic string": lambda: _out(tracks=(_track(dynamic="yes"),)),
    "track age inf": lambda: _out(tracks=(_track(age=math.inf),)),
    "track accel nan": lambda: _out(tracks=(_track(acceleration=np.full(3, np.nan)),)),
    "timings None": lambda: _out(timings_ms=None), "timings nan": lambda: _out(timings_ms={"x": math.nan}),
    "timings object": lambda: _out(timings_ms={"x": object()}), "skipped int": lambda: _out(skipped=5),
    "raises": _raise(ValueError("update failed")), "sys.exit": _raise(SystemExit(0)), "escape": _raise(Escape("x")),
}


class _Perception:
    def __init__(self, update):
        self._update = update

    def reset(self, context=None):
        pass

    def update(self, frame, truth):
        return self._update()


class _Frame:
    stamp = 1.0


@pytest.mark.parametrize("name", list(UPDATES))
def test_a_perception_output_that_is_malformed_becomes_a_counted_skip(name, capsys):
    guard = PerceptionGuard(_Perception(UPDATES[name]), "plug")
    for _ in range(2):
        out = guard.update(_Frame(), None)
        assert isinstance(out, PerceptionOutput) and out.obstacles == () and out.skipped.startswith("error:")
    assert guard.errors.count == 2
    err = capsys.readouterr().err
    assert err.count("failed at t =") == 1
    assert len(err) < 20_000


def test_a_wellformed_perception_output_goes_through():
    good = _out(obstacles=(_obstacle(),), tracks=(_track(),
                                                  {"id": 2, "center": [0, 0, 0], "size": [1, 1, 1], "dynamic": False}),
                timings_ms={"detect": 1.5})
    out = PerceptionGuard(_Perception(lambda: good), "plug").update(_Frame(), None)
    assert len(out.obstacles) == 1 and len(out.tracks) == 2 and out.skipped is None


# --------------------------------------------------------------------------- end to end (slow)

E2E = {
    "planner raises in plan": ("planner", "raise RuntimeError('plan boom')", "plan boom", 1),
    "planner exits 0 in plan": ("planner", "import sys; sys.exit(0)", "SystemExit", 1),
    "planner returns empty": ("planner", "return Trajectory(0.0, 0.1, np.zeros((1, 3)), np.zeros((1, 3)), np.zeros((0, 3)))",
                              "Trajectory.accelerations", 1),
    "perception raises in update": ("perception", "raise RuntimeError('update boom')", "update boom", 1),
    "perception exits in update": ("perception", "import sys; sys.exit(0)", "SystemExit", 1),
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(E2E))
def test_a_failing_plugin_in_a_real_episode_exits_1_with_one_traceback(name, tmp_path):
    role, line, fragment, status = E2E[name]
    method = "plan(self, inp)" if role == "planner" else "update(self, frame, truth)"
    src = textwrap.dedent(f"""
        import numpy as np
        from planner.types import Trajectory
        class P:
            uses_images = False
            def reset(self, context=None):
                pass
            def {method}:
                {line}
    """)
    path = tmp_path / "plug.py"
    path.write_text(src)
    args = ["run", "corridor", "--out", str(tmp_path / "out"), "--duration", "0.5", f"--{role}", f"{path}:P"]
    if role == "planner":
        args += ["--perception", "oracle"]
    r = subprocess.run([sys.executable, "-m", "experiments.cli", *args], capture_output=True, text=True, timeout=300)
    assert_refused(r.returncode, r.stderr, fragment, status=status, plugin=None if "Trajectory" in fragment else "plug.py")
    assert (tmp_path / "out" / "summary.json").exists()
