"""The reproduction report, at the smallest size that exercises every part."""
from pathlib import Path

import pytest

from dodt.pipeline import MODULES
from experiments.bench_perception import PAPER_TABLE_II
from experiments.reproduce import (DIFFERENCES, NAV_HEADER, Plan, _folder, _md_rates, _md_runtime_row, reproduce,
                                   runtime_rows)

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


def test_what_differs_describes_the_renderer_and_the_crowd_in_use():
    text = " ".join(DIFFERENCES.split())
    assert "gl_renderer" in text and "social force" in text
    assert "walk through each other" not in text and "render depth with PyBullet" not in text


def _rate(rate, lo, hi):
    return {"count": 0, "rate": rate, "ci95": [lo, hi]}


def test_a_navigation_row_has_the_at_fault_rate_with_its_interval():
    agg = {"perception": "dodt", "episodes": 10,
           "rates": {"success": _rate(0.6, 0.31, 0.83), "collision": _rate(0.3, 0.11, 0.6),
                     "at_fault": _rate(0.2, 0.057, 0.51), "timeout": _rate(0.1, 0.018, 0.4)},
           "time_to_goal": {"median": 17.5}, "mean_speed": {"median": 0.9}}
    row = _md_rates(agg)
    assert row.count("|") == NAV_HEADER.count("|")
    cells = dict(zip([c.strip() for c in NAV_HEADER.split("|")], [c.strip() for c in row.split("|")]))
    assert cells["at fault"] == "20.0 % [5.7, 51.0]"
    assert cells["collision"] == "30.0 % [11.0, 60.0]"


def _runtime(learned_ms: float, share: bool = False) -> dict:
    rt = {m: {"median_ms": 1.0 + i, "p95_ms": 2.0 + i} for i, m in enumerate(MODULES + ("total",))}
    rt["learned"] = {"median_ms": learned_ms, "p95_ms": learned_ms}
    if share:  # run_runtime adds this figure when the learned detector ran
        rt["learned_share_of_detectors_pct"] = 70.0
    return rt


def test_table_ii_says_the_learned_detector_was_not_run_instead_of_0_ms():
    rows = runtime_rows(_runtime(0.0), "dodt")
    assert [r[0] for r in rows] == list(MODULES) + ["total"]
    learned = next(r for r in rows if r[0] == "learned")
    assert learned[1] is None and learned[2] is None and learned[3] == PAPER_TABLE_II["learned"]
    line = _md_runtime_row(*learned, "dodt")
    assert "not run" in line and "0.00" not in line and "14.30" in line


def test_table_ii_shows_the_learned_detectors_measured_time_when_it_ran():
    rows = runtime_rows(_runtime(12.5, share=True), "dodt+yolo")
    assert [r[0] for r in rows] == list(MODULES) + ["total"]
    learned = next(r for r in rows if r[0] == "learned")
    assert _md_runtime_row(*learned, "dodt+yolo") == "| learned | 12.50 | 12.50 | 14.30 |"
