"""--planner / --perception module:Class: loading, and one-line errors for bad specs."""
import json
import textwrap

import pytest

from experiments.cli import main
from experiments.plugins import load_class
from experiments.registry import make_planner, planner_label

PLUGINS = textwrap.dedent('''
    class Good:
        def reset(self): pass
        def plan(self, inp): raise RuntimeError("unused")

    class NoPlan:
        def reset(self): pass

    class NeedsArgs:
        def __init__(self, x): pass
        def reset(self): pass
        def plan(self, inp): pass

    class Perc:
        name = "mine"
        def reset(self): pass
        def update(self, frame, truth=None): pass

    not_a_class = 3
''')


@pytest.fixture
def plugin_file(tmp_path, monkeypatch):
    f = tmp_path / "my_plugins.py"
    f.write_text(PLUGINS)
    monkeypatch.syspath_prepend(str(tmp_path))
    return f


def test_a_file_and_a_dotted_module_give_the_class(plugin_file):
    assert load_class(f"{plugin_file}:Good").__name__ == "Good"
    assert load_class("my_plugins:Good").__name__ == "Good"
    assert type(make_planner("my_plugins:Good", 0.3)).__name__ == "Good"
    assert type(make_planner("default", 0.3)).__name__ == "PassiveSafetyShield"
    shielded = make_planner("my_plugins:Good", 0.3, shield=True)
    assert type(shielded).__name__ == "PassiveSafetyShield" and type(shielded.planner).__name__ == "Good"
    assert planner_label(None) == "PassiveSafetyShield" and planner_label("my_plugins:Good") == "my_plugins:Good"
    assert planner_label("my_plugins:Good", shield=True) == "shield+my_plugins:Good"


@pytest.mark.parametrize("option, spec, fragment", [
    ("--planner", "{dir}/missing.py:Good", "--planner: no such file"),
    ("--planner", "no_such_module_xyz:Good", "--planner: no such module 'no_such_module_xyz'"),
    ("--planner", "{file}:Missing", "has no class 'Missing'"),
    ("--planner", "{file}:not_a_class", "'not_a_class' is not a class"),
    ("--planner", "{file}:NoPlan", "NoPlan does not implement the planner protocol (planner.types.Planner): no plan()"),
    ("--planner", "{file}:NeedsArgs", "NeedsArgs() (no arguments) failed: TypeError"),
    ("--planner", "{file}:", "expected module:Class"),
    ("--planner", "fancy", "--planner: unknown planner 'fancy'"),
    ("--perception", "{file}:Good", "Good does not implement the perception protocol"),
    ("--perception", "nonsense", "--perception: unknown mode 'nonsense'"),
])
def test_bad_specs_are_one_line_errors(plugin_file, tmp_path, capsys, option, spec, fragment):
    spec = spec.format(dir=tmp_path, file=plugin_file)
    rc = main(["run", "corridor", "--out", str(tmp_path / "out"), option, spec])
    err = capsys.readouterr().err
    assert rc == 2
    assert err.startswith(f"dodt-nav: error: {option}") and fragment in err, err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_a_file_that_fails_to_import_is_one_line(tmp_path, capsys):
    f = tmp_path / "broken.py"
    f.write_text("def oops(:\n")
    rc = main(["sweep", "corridor", "--out", str(tmp_path / "out"), "--planner", f"{f}:X"])
    err = capsys.readouterr().err
    assert rc == 2 and "--planner: importing" in err and "SyntaxError" in err and err.count("\n") == 1


def test_run_with_a_plugin_planner(tmp_path, monkeypatch):
    (tmp_path / "still2.py").write_text(textwrap.dedent('''
        import numpy as np
        from planner.types import Trajectory

        class Hover:
            def reset(self): pass
            def plan(self, inp):
                p = np.repeat(inp.position[None], 11, axis=0)
                return Trajectory(t0=inp.stamp, dt=0.1, positions=p, velocities=np.zeros((11, 3)),
                                  accelerations=np.zeros((10, 3)), status="hover")
    '''))
    monkeypatch.syspath_prepend(str(tmp_path))
    out = tmp_path / "out"
    rc = main(["run", "corridor", "--seed", "0", "--duration", "1", "--map", "truth", "--perception", "oracle",
               "--out", str(out), "--planner", "still2:Hover"])
    s = json.loads((out / "summary.json").read_text())
    assert rc == 0 and s["planner"] == "still2:Hover" and s["perception"] == "oracle"
    assert s["path_length"] < 0.3 and s["config"]["set"] == {} and "navigator" not in s["config"]
