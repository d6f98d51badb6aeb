"""The reproduction report, at the smallest size that exercises every part."""
import pytest

from experiments.reproduce import Plan, reproduce

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
    report = reproduce(tmp_path / "rep", jobs=1, plan=plan, scenario=str(scn))
    text = report.read_text()
    for part in ("Table I", "Table II", "| oracle | 2 |", "| static-only | 1 |", "What differs", "Environment (",
                 "compiled for"):
        assert part in text, part
    # Every figure the report embeds exists.
    import re

    for img in re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text):
        assert (report.parent / img).is_file(), img
    assert (tmp_path / "rep" / "nav_oracle" / "results.jsonl").read_text().count("\n") == 2
