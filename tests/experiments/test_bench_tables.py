"""The perception benchmark's table writer (experiments.bench_perception.write_tables)."""
import csv

import numpy as np
import pytest

from experiments.bench_perception import record_frames, run_runtime, write_tables
from experiments.perception_metrics import PerceptionMetrics


def _summary(pos, vel, fp, visible, recalled):
    m = PerceptionMetrics()
    m.pos_err, m.vel_err, m.pos_err_3d = [pos], [vel], [pos]
    m.dynamic_reports, m.false_dynamic = 100, fp
    m.visible_people, m.recalled_people = visible, recalled
    return m


def test_per_seed_rows_show_each_draw_and_the_overall_row_pools_them(tmp_path):
    seeds = {0: _summary(0.05, 0.10, 1, 100, 96), 1: _summary(0.09, 0.20, 3, 100, 90)}
    overall = {"dodt": PerceptionMetrics.combine(list(seeds.values()))}
    per_scn = {"circles": overall}
    per_seed = {k: {"dodt": m.summary()} for k, m in seeds.items()}
    text = write_tables(tmp_path, overall, per_scn, per_seed)
    assert "| dodt (DODT) | 0.070 | 0.150 | 2.0 | 93.0 |" in text  # pooled: means of the pairs, sums of the counts
    assert "| Method | seed 0 | seed 1 |" in text
    assert "| dodt | 0.050 / 0.100 / 1.0 / 96.0 | 0.090 / 0.200 / 3.0 / 90.0 |" in text
    rows = list(csv.DictReader(open(tmp_path / "table.csv")))
    assert rows[0]["configuration"] == "dodt" and float(rows[0]["recall_pct"]) == 93.0


def test_one_seed_writes_no_per_seed_section(tmp_path):
    overall = {"dodt": _summary(0.05, 0.10, 1, 100, 96).summary()}
    text = write_tables(tmp_path, overall, {"circles": overall}, {0: overall})
    assert "Per seed" not in text


def test_std_scale_is_one_for_a_calibrated_std_and_halves_when_the_std_is_doubled(tmp_path):
    rng = np.random.default_rng(0)
    sigma = 0.1
    err = np.hypot(*rng.normal(0.0, sigma, (2, 20000)))  # isotropic, sigma per axis
    calibrated, doubled = PerceptionMetrics(), PerceptionMetrics()
    calibrated.std_ratio = list(err / sigma)
    doubled.std_ratio = list(err / (2 * sigma))
    assert abs(calibrated.summary()["std_scale"] - 1.0) < 0.03
    assert abs(doubled.summary()["std_scale"] - 0.5) < 0.015
    overall = {"dodt": doubled.summary()}
    overall["dodt"].update(pos_err=0.05, vel_err=0.1, recall=0.9)
    text = write_tables(tmp_path, overall, {"circles": overall})
    assert "calibrated, below 1 when the std overstates the error): dodt 0.50." in text
    assert abs(float(next(csv.DictReader(open(tmp_path / "table.csv")))["std_scale"]) - 0.5) < 0.015


def test_prediction_errors_are_a_line_of_the_table_and_columns_of_the_csv(tmp_path):
    m = PerceptionMetrics()
    m.pred_cv, m.pred_ca = [0.2, 0.4], [0.5, 0.7]
    overall = {"dodt": m.summary()}
    overall["dodt"].update(pos_err=0.05, vel_err=0.1, recall=0.9)
    text = write_tables(tmp_path, overall, {"circles": overall})
    assert "with the filter's acceleration held: dodt 0.30 / 0.60." in text
    row = next(csv.DictReader(open(tmp_path / "table.csv")))
    assert (float(row["pred_err_cv_m"]), float(row["pred_err_ca_m"])) == (0.3, 0.6)


def test_runtime_on_a_lidar_rig_times_the_lidar_on_the_frames_a_scan_joined(capsys):

    rec = record_frames("corridor", 0.5, rig_name="lidar")
    assert all(len(r) == 3 for r in rec) and [r[2] is not None for r in rec[:6]] == [True, False, False] * 2
    res = run_runtime("dodt", "corridor", seconds=0.5, repeats=1, rig_name="lidar")
    assert res["lidar"]["median_ms"] > 0.0
    out = capsys.readouterr().out
    assert "LiDAR detection, fusion" in out and "other cameras" not in out
