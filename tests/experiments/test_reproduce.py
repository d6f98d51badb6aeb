"""The reproduction report, at the smallest size that exercises every part."""
from pathlib import Path

import pytest

from experiments.reproduce import Plan, _folder, reproduce

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"

SHORT = """
name = "short"
duration = 4.0
[corridor]
length = 6.0
width = 4.0
height = 3.0
[[people]]
behaviour = "crossing"
speed = 0.8
waypoints = [[3.0, 1.5], [3.0, -1.5]]
[drone]
start = [0.5, 0.0, 1.2]
goal = [5.5, 0.0, 1.2]
"""


@pytest.mark.slow
def test_reproduce_writes_a_report_with_every_part(tmp_path):
    scn = tmp_path / "short.toml"
    scn.write_text(SHORT)
    plan = Plan(perception_configs=("dodt",), perception_scenarios=("wall_pass",), perception_duration=2.0,
                runtime_seconds=1.0, nav_seeds={"oracle": 2, "static-only": 1})
    near = str(EXAMPLES / "custom_perception.py") + ":NearDODT"
    report = reproduce(tmp_path / "rep", jobs=1, plan=plan, scenario=str(scn), perception=(near,))
    text = report.read_text()
    for part in ("Table I", "Table II", "| oracle | 2 |", "| static-only | 1 |", f"| {near} | 2 |", "What differs",
                 "Environment (", "compiled for"):
        assert part in text, part
    # Every figure the report embeds exists.
    import re

    for img in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (report.parent / img).is_file(), img
    assert (tmp_path / "rep" / "nav_oracle" / "results.jsonl").read_text().count("\n") == 2
    assert (tmp_path / "rep" / _folder(near) / "results.jsonl").read_text().count("\n") == 2


def test_a_plugins_sweep_folder_is_a_plain_name():
    assert _folder("dodt") == "nav_dodt"
    name = _folder("examples/custom_perception.py:NearDODT")
    assert name == "nav_examples_custom_perception.py_NearDODT" and "/" not in name and ":" not in name
