"""dodt-nav compare: two sweeps paired seed by seed, the exact sign test, the regression gate."""
import json
import math

import pytest

from experiments.cli import main
from experiments.compare_sweeps import CompareError, compare_sweeps, format_comparison, paired_interval, sign_test_p


ENV = {"python": "3.11.7", "packages": {"numpy": "2.4.6", "numba": "0.68.1"}, "cpu": "znver5",
       "cpu_model": "AMD EPYC", "numpy_simd": ["AVX2", "AVX512F"], "renderer": "egl"}


def _sweep(folder, outcomes, scenario="corridor", cut_last_line=False, env=ENV):
    """A results.jsonl as dodt-nav sweep writes it: outcomes maps seed -> 'ok', 'collision' or 'timeout';
    env: the environment each episode records (None: none recorded, as results written before it was)."""
    folder.mkdir(parents=True, exist_ok=True)
    lines = []
    for seed, o in outcomes.items():
        row = {"scenario": scenario, "seed": seed, "perception": "dodt", "static_map": "depth",
               "frame_latency": 1, "success": o == "ok", "collided": o == "collision",
               "timeout": o == "timeout", "failure_reason": None if o == "ok" else o,
               "mean_speed": 1.0 + seed / 100}
        if env is not None:
            row["environment"] = env(seed) if callable(env) else env
        lines.append(json.dumps(row))
    text = "\n".join(lines) + "\n"
    if cut_last_line:
        text += '{"scenario": "corridor", "seed": 99, "succ'  # a line cut short by a kill
    (folder / "results.jsonl").write_text(text)
    return folder


@pytest.mark.parametrize("k,n,expected", [
    (0, 0, 1.0), (0, 1, 1.0), (3, 10, 11 / 32), (5, 10, 1.0), (22, 67, 62178877096773739 / 2**63),
    (45, 67, 62178877096773739 / 2**63), (0, 20, 1 / 2**19), (12, 30, 194129627 / 2**29),
])
def test_sign_test_is_the_exact_two_sided_binomial_test(k, n, expected):
    # expected: twice the smaller tail, sum_{i <= min(k, n - k)} C(n, i) / 2^n, at most 1, as exact fractions
    assert sign_test_p(k, n) == pytest.approx(expected, rel=1e-12)


def test_paired_interval_is_the_wald_interval_for_many_seeds_and_mirrors_when_swapped():
    # 2000 seeds, 400 changed (230 up, 170 down): Newcombe's interval is close to the Wald one
    d, lo, hi = paired_interval(1000, 230, 170, 600)
    n, up, down = 2000, 230, 170
    se = math.sqrt(up + down - (up - down) ** 2 / n) / n
    assert d == pytest.approx((up - down) / n)
    assert lo == pytest.approx(d - 1.96 * se, abs=0.002) and hi == pytest.approx(d + 1.96 * se, abs=0.002)
    # the sweeps swapped: the same interval, mirrored
    d2, lo2, hi2 = paired_interval(1000, 170, 230, 600)
    assert (d2, lo2, hi2) == pytest.approx((-d, -hi, -lo))


@pytest.mark.parametrize("both,up,down,neither", [(30, 0, 0, 10), (29, 10, 1, 0), (0, 0, 0, 5), (5, 5, 0, 0),
                                                   (0, 3, 4, 0)])
def test_paired_interval_holds_the_difference_within_minus_one_to_one(both, up, down, neither):
    d, lo, hi = paired_interval(both, up, down, neither)
    assert -1.0 <= lo <= d <= hi <= 1.0 and lo < hi


def test_paired_interval_excludes_zero_where_the_sign_test_rejects_and_not_where_it_does_not():
    assert paired_interval(29, 10, 1, 0)[1] > 0  # 10 of 11 changed seeds up, 40 seeds: p = 0.0117
    assert paired_interval(100, 12, 8, 80)[1] < 0 < paired_interval(100, 12, 8, 80)[2]  # p = 0.50


def test_sign_test_rejects_impossible_counts():
    with pytest.raises(ValueError, match="k must lie"):
        sign_test_p(5, 3)


def test_seeds_are_paired_and_only_the_changed_ones_count(tmp_path):
    base = {s: "ok" for s in range(40)}
    new = dict(base)
    for s in range(10):  # ten seeds fail in the baseline and succeed with the change
        base[s] = "collision"
    new[20] = "timeout"  # one goes the other way
    base[50] = "ok"  # only in the baseline: left out
    c = compare_sweeps(_sweep(tmp_path / "a", base), _sweep(tmp_path / "b", new, cut_last_line=True))
    assert c.seeds == tuple(range(40)) and c.only_in_base == 1 and c.only_in_new == 0
    assert (c.base_success, c.new_success) == (30, 39)
    assert c.to_success == tuple(range(10)) and c.to_failure == ((20, "timeout"),)
    assert c.p_value == pytest.approx(3 / 256)  # 10 of 11 changed seeds one way: 2 (1 + 11) / 2^11
    # rows without classified contacts (written before collisions had a fault class) count as at fault
    assert c.counts == {"collision": (10, 0), "at-fault collision": (10, 0), "only not-at-fault collisions": (0, 0),
                        "timeout": (0, 1)}
    assert c.verdict.startswith("better")
    # each outcome class paired the same way: seeds with it in the baseline only, in the change only, p
    assert c.changes["at-fault collision"][:3] == (10, 0, pytest.approx(2 / 1024))
    assert c.changes["timeout"][:3] == (0, 1, 1.0) and c.changes["only not-at-fault collisions"][:3] == (0, 0, 1.0)
    assert c.changes["success"][:3] == (1, 10, pytest.approx(3 / 256))
    d, lo, hi = c.changes["at-fault collision"][3]
    assert d == pytest.approx(-0.25) and lo < d < hi < 0  # 25 % fewer, an interval clear of zero
    text = format_comparison(c)
    assert "turned to failure (1): 20 (timeout)" in text and "1 only in the baseline" in text
    assert "| success | 30 (75.0 %) | 39 (97.5 %) | +22.5 [" in text and "points | 1 / 10, p = 0.0117 |" in text
    assert "| at-fault collision | 10 (25.0 %) | 0 (0.0 %) | -25.0 [" in text and "| 10 / 0, p = 0.00195 |" in text
    # the same seeds the other way round: worse, same p
    r = compare_sweeps(tmp_path / "b" / "results.jsonl", tmp_path / "a")
    assert r.verdict.startswith("worse") and r.p_value == c.p_value


def test_a_small_difference_is_called_churn_not_a_gain(tmp_path):
    base = {s: ("ok" if s % 4 else "collision") for s in range(100)}  # 75 %
    new = dict(base)
    for s in (0, 4, 8, 12, 16, 20, 24):  # 7 seeds to success ...
        new[s] = "ok"
    for s in (1, 2, 3, 5):  # ... 4 to failure: 78 % against 75 %
        new[s] = "collision"
    c = compare_sweeps(_sweep(tmp_path / "a", base), _sweep(tmp_path / "b", new))
    assert c.new_success - c.base_success == 3
    assert c.p_value > 0.5 and c.verdict.startswith("no clear difference")


def test_sweeps_of_different_scenarios_are_compared_with_a_warning(tmp_path):
    c = compare_sweeps(_sweep(tmp_path / "a", {0: "ok", 1: "ok"}),
                       _sweep(tmp_path / "b", {0: "ok", 1: "ok"}, scenario="circles"))
    assert c.warnings and "scenario" in c.warnings[0]
    assert c.verdict == "no seed changed outcome"


def test_sweeps_from_different_machines_or_installations_are_compared_with_a_warning(tmp_path):
    same = compare_sweeps(_sweep(tmp_path / "a", {0: "ok", 1: "collision"}),
                          _sweep(tmp_path / "b", {0: "collision", 1: "ok"}))
    assert same.warnings == ()
    other = {**ENV, "cpu": "skylake-avx512", "packages": {**ENV["packages"], "numpy": "2.4.5"}}
    c = compare_sweeps(tmp_path / "a", _sweep(tmp_path / "c", {0: "collision", 1: "ok"}, env=other))
    assert len(c.warnings) == 1
    w = c.warnings[0]
    assert "different environments" in w and "cpu znver5 against skylake-avx512" in w
    assert "numpy 2.4.6 against 2.4.5" in w and "numba" not in w  # only what differs is named
    assert "warning: the sweeps ran in different environments" in format_comparison(c)
    # one sweep resumed on another machine: its episodes disagree among themselves
    mixed = _sweep(tmp_path / "d", {0: "ok", 1: "ok"}, env=lambda seed: other if seed else ENV)
    assert any("change's episodes ran in 2 environments" in w for w in compare_sweeps(tmp_path / "a", mixed).warnings)
    # results written before episodes recorded their environment: unknown, said so
    old = compare_sweeps(_sweep(tmp_path / "e", {0: "ok", 1: "ok"}, env=None), tmp_path / "a")
    assert len(old.warnings) == 1 and "baseline record no environment" in old.warnings[0]


def test_nothing_to_compare_is_a_clear_error(tmp_path):
    a = _sweep(tmp_path / "a", {0: "ok"})
    with pytest.raises(CompareError, match="no seed in common"):
        compare_sweeps(a, _sweep(tmp_path / "b", {1: "ok"}))
    with pytest.raises(CompareError, match="no results.jsonl"):
        compare_sweeps(a, tmp_path / "missing")
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "results.jsonl").write_text("")
    with pytest.raises(CompareError, match="no finished episode"):
        compare_sweeps(a, tmp_path / "empty")


def test_the_cli_gate_fails_only_a_significant_regression(tmp_path, capsys):
    good = _sweep(tmp_path / "good", {s: "ok" for s in range(30)})
    bad = _sweep(tmp_path / "bad", {s: ("collision" if s < 12 else "ok") for s in range(30)})
    slightly = _sweep(tmp_path / "slightly", {s: ("collision" if s < 2 else "ok") for s in range(30)})
    assert main(["compare", str(good), str(bad), "--fail-if-worse", "0.05"]) == 1  # 12 to failure, none back
    assert "worse than the baseline" in capsys.readouterr().err
    assert main(["compare", str(good), str(slightly), "--fail-if-worse", "0.05"]) == 0  # 2 of 2: p = 0.5
    assert main(["compare", str(bad), str(good), "--fail-if-worse", "0.05"]) == 0  # better passes
    assert main(["compare", str(good), str(bad)]) == 0  # no gate asked
    assert "verdict: worse" in capsys.readouterr().out
    assert main(["compare", str(good), str(bad), "--fail-if-worse", "2"]) == 2
    assert main(["compare", str(good), str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err
    assert "--fail-if-worse" in err and "nowhere" in err and "Traceback" not in err


def test_the_environment_record_names_versions_processor_and_overrides(monkeypatch):
    """What an episode records of its environment: the packages' versions as installed, the processor
    numba compiles for, and the variables set by hand that change how the libraries compute."""
    import numpy as np

    from experiments.environment import differences, environment, fingerprint

    environment.cache_clear()
    monkeypatch.setenv("GALLIUM_NOSSE", "1")
    try:
        env = environment()
    finally:
        environment.cache_clear()
    assert env["packages"]["numpy"] == np.__version__ and env["cpu"]
    assert env["overrides"]["GALLIUM_NOSSE"] == "1"
    plain = {**env, "overrides": {k: v for k, v in env["overrides"].items() if k != "GALLIUM_NOSSE"}}
    assert fingerprint(plain) != fingerprint(env)
    assert differences(plain, env) == [f"overrides {plain['overrides']} against {env['overrides']}"]
    json.dumps(env)  # it goes into summary.json


def test_the_renderers_older_name_is_the_same_renderer():
    """Episodes recorded PyBullet's EGL plugin as "egl" before it was named "pybullet": the same renderer, so
    no difference; our gl renderer is another."""
    from experiments.environment import differences, fingerprint

    new = {**ENV, "renderer": "pybullet"}
    assert fingerprint(ENV) == fingerprint(new) and differences(ENV, new) == []
    gl = {**ENV, "renderer": "gl"}
    assert differences(ENV, gl) == ["renderer egl against gl"]
