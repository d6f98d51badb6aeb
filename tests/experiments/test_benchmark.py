"""The navigation benchmark (experiments.benchmark): splits, cells as resumable sweeps, the report."""
import json

import pytest

from experiments import benchmark
from experiments.cli import main
from experiments.episode import EpisodeConfig
from experiments.sweep import SweepError


def test_splits_are_disjoint_and_named():
    dev, test = benchmark.split_seeds("dev", 1000), benchmark.split_seeds("test", 1000)
    assert dev[0] == 0 and test[0] == 1000 and not set(dev) & set(test)
    assert benchmark.split_seeds("test", 3) == [1000, 1001, 1002]
    with pytest.raises(SweepError, match="--split: 'val' is not one of dev, test"):
        benchmark.split_seeds("val", 3)
    with pytest.raises(SweepError, match="--seeds: must be between 1 and 1000"):
        benchmark.split_seeds("dev", 0)


def test_a_seed_span_names_fresh_seeds_inside_its_split():
    assert benchmark.split_seeds("dev", "200:203") == [200, 201, 202]
    assert benchmark.split_seeds("test", "1998:2000") == [1998, 1999]
    assert benchmark.split_seeds("dev", "5") == [0, 1, 2, 3, 4]
    for span in ("990:1010", "1000:1002", "7:7", "9:3"):
        with pytest.raises(SweepError, match=f"--seeds: '{span}' must be a non-empty range within the dev split's"
                                             " seeds 0-999"):
            benchmark.split_seeds("dev", span)
    with pytest.raises(SweepError, match="within the test split's seeds 1000-1999"):
        benchmark.split_seeds("test", "0:10")
    with pytest.raises(SweepError, match="'a:b' is not N or start:stop"):
        benchmark.split_seeds("dev", "a:b")


def test_benchmark_nav_rejects_a_seed_span_outside_its_split(tmp_path, capsys):
    assert main(["benchmark", "nav", "--split", "test", "--seeds", "0:3", "--families", "head_on",
                 "--perception", "oracle", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "--seeds: '0:3' must be a non-empty range within the test split's seeds 1000-1999" in err
    assert "Traceback" not in err
    assert main(["benchmark", "nav", "--seeds", "1:2:3", "--out", str(tmp_path / "c")]) == 2
    assert "must be N or start:stop (whole numbers), got '1:2:3'" in capsys.readouterr().err


@pytest.mark.slow
def test_a_small_benchmark_writes_its_report_and_resumes(tmp_path):
    cfg = EpisodeConfig(static_map="truth")
    report = benchmark.run_benchmark(tmp_path, "dev", 1, ("head_on", "static_clutter"), ("oracle",),
                                     ("blind", "aware"), jobs=1, cfg=cfg, progress=False)
    cells = {(r["family"], r["people"], r["perception"]): r for r in report["cells"]}
    # static_clutter has nobody who could see the drone: one setting only
    assert set(cells) == {("head_on", "blind", "oracle"), ("head_on", "aware", "oracle"),
                          ("static_clutter", "blind", "oracle")}
    for r in cells.values():
        assert r["episodes"] == 1 and set(benchmark.REPORTED) <= set(r["rates"])
    aware = [json.loads(x) for x in (tmp_path / "head_on/aware/oracle/results.jsonl").read_text().splitlines()]
    blind = [json.loads(x) for x in (tmp_path / "head_on/blind/oracle/results.jsonl").read_text().splitlines()]
    assert aware[0]["people_see_drone"] and not blind[0]["people_see_drone"]
    md = (tmp_path / "report.md").read_text()
    assert "| head_on | aware | oracle | front | 1 |" in md and "dev split (seeds 0-0)" in md
    assert (tmp_path / "plots" / "head_on.png").stat().st_size > 1000
    # rerun: nothing left to run, the same report
    again = benchmark.run_benchmark(tmp_path, "dev", 1, ("head_on", "static_clutter"), ("oracle",),
                                    ("blind", "aware"), jobs=1, cfg=cfg, progress=False)
    assert again["cells"] == report["cells"]
    # a span over the seed already run adds only the one missing, and names its seeds
    span = benchmark.run_benchmark(tmp_path, "dev", "0:2", ("head_on",), ("oracle",), ("blind",), jobs=1, cfg=cfg,
                                   progress=False)
    assert span["seeds"] == [0, 1] and span["cells"][0]["episodes"] == 2
    seeds = [json.loads(x)["seed"] for x in (tmp_path / "head_on/blind/oracle/results.jsonl").read_text().splitlines()]
    assert seeds == [0, 1] and "dev split (seeds 0-1)" in (tmp_path / "report.md").read_text()
    # the same folder with another configuration is refused
    with pytest.raises(SweepError, match="holds results of another configuration"):
        benchmark.run_benchmark(tmp_path, "dev", 1, ("head_on",), ("oracle",), ("blind",), cfg=EpisodeConfig(),
                                progress=False)


@pytest.mark.parametrize("args,message", [
    (["--split", "val"], "invalid choice: 'val'"),
    (["--people", "blind,deaf"], "--people: 'deaf' is not one of blind, aware"),
    (["--families", "nowhere"], "nowhere: no such file, and not a shipped scenario"),
    (["--perception", "psychic"], "psychic"),
    (["--jobs", "0"], "--jobs: must be >= 1"),
])
def test_bad_benchmark_options_are_one_line_errors(args, message, tmp_path, capsys):
    try:
        code = main(["benchmark", "nav", "--out", str(tmp_path), *args])
    except SystemExit as e:  # argparse's own refusals
        code = e.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
