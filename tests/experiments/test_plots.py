"""experiments.episode_plots, sweep_plots and runtime_plots: episode and sweep figures are valid, non-blank
PNGs drawn from real logs and results."""
import copy
import gzip
import json
import struct

import numpy as np
import pytest

from experiments.episode import EpisodeConfig, run_episode
from experiments.episode_log import read_log
from experiments.cli import main
from experiments.episode_plots import (EPISODE_FILES, clearance_figure, episode_runtime_rows, match_tracks_to_people,
                                      plot_episode)
from experiments.runtime_plots import plot_runtime_table, runtime_table_figure
from experiments.sweep_plots import SWEEP_FILES, plot_sweep

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def png_pixels(path) -> np.ndarray:
    """Checks the file is a PNG of plausible size and returns its RGB pixels (H, W, 3) uint8."""
    from PIL import Image

    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE, f"{path}: not a PNG"
    assert data[12:16] == b"IHDR"
    w, h = struct.unpack(">II", data[16:24])
    assert 200 <= w <= 3000 and 150 <= h <= 3000, f"{path}: implausible size {w}x{h}"
    with Image.open(path) as im:
        im.verify()
    with Image.open(path) as im:
        a = np.asarray(im.convert("RGB"))
    assert a.shape == (h, w, 3)
    return a


def assert_not_blank(a: np.ndarray, min_ink: float = 0.005) -> None:
    assert a.astype(float).std() > 5.0
    assert (a.min(axis=-1) < 200).mean() > min_ink  # a share of pixels is drawn on


def red_pixels(a: np.ndarray) -> int:
    """Pixels of the collision colour (pure red)."""
    return int(((a[..., 0] > 240) & (a[..., 1] < 30) & (a[..., 2] < 30)).sum())


@pytest.fixture(scope="module")
def oracle_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("oracle_run")
    summary = run_episode("corridor", seed=0, perception="oracle", out=out, cfg=EpisodeConfig(duration=3.0))
    return out, summary


@pytest.fixture(scope="module")
def dodt_run(tmp_path_factory):
    # People first come within the camera's reach of seed 0 after about 3.5 s.
    out = tmp_path_factory.mktemp("dodt_run")
    summary = run_episode("corridor", seed=0, perception="dodt", out=out, cfg=EpisodeConfig(duration=4.5))
    return out, summary


# --------------------------------------------------------------------------- episode


def test_episode_figures_from_a_real_log_are_valid_and_not_blank(oracle_run, tmp_path):
    run, _ = oracle_run
    paths = plot_episode(run / "log.jsonl.gz", tmp_path / "figs")
    assert [p.name for p in paths] == list(EPISODE_FILES)
    for p in paths:
        assert p.is_file() and p.parent == tmp_path / "figs"
        assert_not_blank(png_pixels(p))
    # The run folder works as well as the log's path.
    assert [p.name for p in plot_episode(run, tmp_path / "from_dir")] == list(EPISODE_FILES)


def test_topdown_and_clearance_mark_collisions_in_red_only_when_logged(oracle_run, tmp_path):
    run, summary = oracle_run
    assert summary["collision_count"] == 0  # 3 s of the corridor: the drone has not reached the people
    records = read_log(run / "log.jsonl.gz")
    clean = plot_episode(records, tmp_path / "clean")
    for p in clean[:2]:
        assert red_pixels(png_pixels(p)) == 0
    hit = copy.deepcopy(records)
    s = [r for r in hit if r["k"] == "s"][len([r for r in hit if r["k"] == "s"]) // 2]
    hit.insert(-1, {"k": "collision", "t": s["t"], "kind": "person", "other_id": 5, "position": s["p"]})
    marked = plot_episode(hit, tmp_path / "hit")
    top, clear = png_pixels(marked[0]), png_pixels(marked[1])
    assert red_pixels(top) > 200  # the big X
    assert red_pixels(clear) > 50  # the vertical line at the collision time
    assert_not_blank(top)


def test_clearance_plots_structure_and_shades_what_the_summary_leaves_out(oracle_run):
    run, summary = oracle_run
    records = read_log(run / "log.jsonl.gz")
    states = [r for r in records if r["k"] == "s"]
    t = np.array([s["t"] for s in states])
    c = np.array([s["c"] for s in states])
    ax = clearance_figure(records).axes[0]
    lines = {line.get_label(): line for line in ax.get_lines()}
    for label, col in (("nearest static obstacle", 0), ("nearest person", 1), ("nearest wall, floor or ceiling", 2)):
        assert np.array_equal(lines[label].get_xdata(), t) and np.array_equal(lines[label].get_ydata(), c[:, col])
    # The take-off, in front of the corridor's end wall, is shaded; the summary's structure clearance is the
    # least of the periods after it, not the 0.24 m to the wall behind the drone at its start.
    p, start = np.array([s["p"] for s in states]), records[0]["start"]
    away = np.hypot(p[:, 0] - start[0], p[:, 1] - start[1]) > 1.0
    assert not away[0] and away[-1]
    (span,) = [patch for patch in ax.patches if "start or goal" in patch.get_label()]
    x0, x1 = span.get_extents().transformed(ax.transData.inverted()).intervalx
    assert x0 == pytest.approx(t[0]) and x1 == pytest.approx(t[np.argmax(away)])
    assert c[0, 2] < 0.3
    assert summary["min_clearance"]["structure"] == c[away, 2].min() > 0.5


def test_perception_error_plots_matched_people_for_dodt(dodt_run, tmp_path):
    run, _ = dodt_run
    records = read_log(run / "log.jsonl.gz")
    matched = match_tracks_to_people(records, 1.0)
    assert matched, "every frame has people from ground truth"
    finite = np.concatenate([pe[np.isfinite(pe)] for _, pe, _ in matched.values()])
    assert len(finite) > 5 and finite.max() <= 1.0
    for t, pe, ve in matched.values():
        assert len(t) == len(pe) == len(ve) and np.all(np.isfinite(pe) == np.isfinite(ve))
    paths = plot_episode(records, tmp_path)
    a = png_pixels(paths[2])
    assert_not_blank(a, min_ink=0.02)
    assert a.shape[0] > 0.65 * a.shape[1]  # the two-panel figure, not the 8x4 "nothing to score" one
    # A tighter gate matches fewer frames.
    tight = match_tracks_to_people(records, 0.05)
    assert sum(np.isfinite(pe).sum() for _, pe, _ in tight.values()) < len(finite)


@pytest.mark.parametrize("mode", ["oracle", "static-only", "no-tracks", "no-match"])
def test_perception_error_says_why_when_there_is_nothing_to_score(oracle_run, tmp_path, mode):
    run, _ = oracle_run
    records = copy.deepcopy(read_log(run / "log.jsonl.gz"))
    if mode != "oracle":
        records[0]["perception"] = "static-only" if mode == "static-only" else "dodt"
        for r in records:
            if r["k"] == "f":
                if mode == "no-match":  # dynamic tracks, all far from every person
                    r["tracks"] = [{"id": 1, "center": [-5.0, -5.0, 1.0], "size": [0.5, 0.5, 1.7],
                                    "velocity": [0.0, 0.0, 0.0], "dynamic": True}]
                else:
                    r["tracks"] = []
    paths = plot_episode(records, tmp_path)
    a = png_pixels(paths[2])
    assert_not_blank(a)
    assert a.shape[0] < 0.6 * a.shape[1]  # the one-panel message figure
    assert all(p.is_file() for p in paths)


def test_runtime_figure_has_three_modules_from_the_log(oracle_run):
    run, _ = oracle_run
    rows = episode_runtime_rows(read_log(run / "log.jsonl.gz"))
    assert [r[0] for r in rows] == ["perception (oracle) per frame", "map update", "planner solve"]
    for _, med, p95, n in rows:
        assert n > 0 and 0 <= med <= p95


# --------------------------------------------------------------------------- runtime table


def test_runtime_table_accepts_rows_paper_values_and_bench_dicts(tmp_path):
    rows = [("point cloud + voxel", 1.2, 2.0), ("U-depth detection", 3.1, 4.0, 3.4),
            ("DBSCAN detection", 0.9, 1.5, 1.3), ("data association", 0.02, 0.05, 0.03), ("no data", None, None)]
    p = plot_runtime_table(rows, tmp_path / "table2.png")
    assert p == tmp_path / "table2.png"
    assert_not_blank(png_pixels(p))
    bench = {"udepth": {"median_ms": 3.0, "p95_ms": 3.5}, "total": {"median_ms": 6.0, "p95_ms": 7.5}}
    assert_not_blank(png_pixels(plot_runtime_table(bench, tmp_path / "bench.png", title="bench")))
    assert_not_blank(png_pixels(plot_runtime_table([], tmp_path / "empty.png")))
    with pytest.raises(ValueError, match="each row must be"):
        plot_runtime_table([("x", 1.0)], tmp_path / "bad.png")


def _legend_clashes(fig, legend) -> list[str]:
    """What the drawn ``legend`` overlaps among the axes' area (the data), its tick labels, title,
    axis labels and value labels."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    canvas = fig.canvas if isinstance(fig.canvas, FigureCanvasAgg) else FigureCanvasAgg(fig)
    canvas.draw()
    r = canvas.get_renderer()
    box = legend.get_window_extent(r)
    ax = fig.axes[0]
    named = [("axes area", ax.get_window_extent(r)), ("title", ax.title.get_window_extent(r)),
             ("x label", ax.xaxis.label.get_window_extent(r))]
    named += [(f"tick label {t.get_text()!r}", t.get_window_extent(r))
              for t in ax.get_xticklabels() + ax.get_yticklabels() if t.get_visible() and t.get_text()]
    named += [(f"value label {t.get_text()!r}", t.get_window_extent(r)) for t in ax.texts]
    return [name for name, bb in named if bb.width > 0 and box.overlaps(bb)]


@pytest.mark.parametrize("paper", [False, True])
def test_runtime_legend_covers_no_label_title_or_data(paper):
    rows = [("perception (oracle) per frame (n=90)", 1.2, 2.0), ("map update (n=90)", 3.1, 4.0),
            ("planner solve (n=30)", 9.0, 14.5)]
    if paper:
        rows = [r + (p,) for r, p in zip(rows, (1.0, 3.4, 1.3))]
    fig = runtime_table_figure(rows, title="corridor seed 0: wall-clock per call, this machine")
    assert len(fig.legends) == 1 and fig.axes[0].get_legend() is None
    legend = fig.legends[0]
    assert [t.get_text() for t in legend.get_texts()] == ["median", "p95"] + ["paper (Intel NUC)"] * paper
    assert _legend_clashes(fig, legend) == []
    inside = fig.bbox.padded(0.5)  # the whole legend is on the figure
    box = legend.get_window_extent(fig.canvas.get_renderer())
    assert inside.x0 <= box.x0 and box.x1 <= inside.x1 and inside.y0 <= box.y0 and box.y1 <= inside.y1
    # The check finds the overlap of the legend this figure had before: in the axes' lower right corner.
    old = fig.axes[0].legend(fontsize=7, loc="lower right")
    assert "axes area" in _legend_clashes(fig, old) and "value label '9.00 / 14.50 ms'" in _legend_clashes(fig, old)


def test_same_input_gives_the_same_png_and_leaves_no_figure_open(tmp_path):
    import matplotlib.pyplot as plt

    before = plt.get_fignums()
    rows = [("a", 1.0, 2.0), ("b", 3.0, 5.0, 4.0)]
    a = plot_runtime_table(rows, tmp_path / "a.png").read_bytes()
    b = plot_runtime_table(rows, tmp_path / "b.png").read_bytes()
    assert a == b
    plot_sweep(synthetic_summaries(12), tmp_path / "sweep")
    assert plt.get_fignums() == before


# --------------------------------------------------------------------------- sweep


def synthetic_summaries(n: int, seed: int = 0) -> list[dict]:
    """Episode summaries with the fields experiments.sweep.aggregate reads (episode_metrics.summarize)."""
    rng = np.random.default_rng(seed)
    out = []
    for s in range(n):
        u = rng.random()
        collided, timeout = u < 0.2, 0.2 <= u < 0.3
        crashed = 0.3 <= u < 0.35
        ok = not (collided or timeout or crashed)
        person = float(rng.uniform(0.0, 0.02)) if collided else float(rng.uniform(0.2, 1.0))
        out.append({
            "scenario": "corridor", "seed": s, "perception": "dodt", "planner": "MPCPlanner",
            "success": ok, "reached_goal": ok, "collided": collided, "collision_count": int(collided),
            "timeout": timeout, "failure_reason": ("collision" if collided else "timeout" if timeout
                                                   else "crashed" if crashed else None),
            "time_to_goal": round(float(rng.normal(11.0, 0.8)), 3) if ok else None,
            "mean_speed": 1.4 if ok else 0.9,
            "min_clearance": {"static": 0.3, "person": person, "structure": 0.25, "overall": min(person, 0.25)},
            "planner_stats": {"plans": 100, "fallbacks": int(rng.integers(0, 3)), "errors": 0},
        })
    return out


def test_sweep_figures_from_summaries(tmp_path):
    paths = plot_sweep(synthetic_summaries(40), tmp_path / "sweep")
    assert [p.name for p in paths] == list(SWEEP_FILES)
    for p in paths:
        assert_not_blank(png_pixels(p))
    strip = png_pixels(paths[3])
    assert red_pixels(strip) > 100  # collided seeds are red cells


def test_sweep_figures_from_a_results_file_with_a_line_cut_short(tmp_path):
    sweep_dir = tmp_path / "sweep"
    sweep_dir.mkdir()
    lines = [json.dumps(s) for s in synthetic_summaries(25, seed=3)]
    (sweep_dir / "results.jsonl").write_text("\n".join(lines) + "\n" + lines[0][:40])  # killed mid-write
    for src in (sweep_dir / "results.jsonl", sweep_dir):
        paths = plot_sweep(src, tmp_path / "figs")
        for p in paths:
            assert_not_blank(png_pixels(p))


def test_sweep_where_nothing_reached_the_goal_still_plots(tmp_path):
    summaries = synthetic_summaries(6)
    for s in summaries:
        s.update(success=False, reached_goal=False, collided=False, timeout=True, time_to_goal=None,
                 failure_reason="timeout")
    summaries[0]["min_clearance"] = {"static": None, "person": None, "structure": None, "overall": None}
    paths = plot_sweep(summaries, tmp_path)
    for p in paths:
        assert_not_blank(png_pixels(p))


def test_sweep_figures_from_real_episode_summaries(oracle_run, tmp_path):
    _, summary = oracle_run
    other = dict(summary, seed=summary["seed"] + 1)
    paths = plot_sweep([summary, other], tmp_path)
    for p in paths:
        assert_not_blank(png_pixels(p))


# --------------------------------------------------------------------------- errors


def test_missing_and_wrong_inputs_raise_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="nope.jsonl.gz: no such episode log"):
        plot_episode(tmp_path / "nope.jsonl.gz", tmp_path / "o")
    with pytest.raises(FileNotFoundError, match="no log.jsonl.gz in this folder"):
        plot_episode(tmp_path, tmp_path / "o")
    (tmp_path / "plain.txt").write_text("hello\n")
    with pytest.raises(ValueError, match="plain.txt: not a gzip-compressed episode log"):
        plot_episode(tmp_path / "plain.txt", tmp_path / "o")
    with gzip.open(tmp_path / "nohead.jsonl.gz", "wt") as fh:
        fh.write(json.dumps({"k": "s", "t": 0.0}) + "\n")
    with pytest.raises(ValueError, match="no header record"):
        plot_episode(tmp_path / "nohead.jsonl.gz", tmp_path / "o")
    with pytest.raises(ValueError, match="first record must be the header"):
        plot_episode([{"k": "s", "t": 0.0}], tmp_path / "o")
    with pytest.raises(ValueError, match="first record must be the header"):
        plot_episode([], tmp_path / "o")
    with pytest.raises(FileNotFoundError, match="results.jsonl: no such sweep results file"):
        plot_sweep(tmp_path / "results.jsonl", tmp_path / "o")
    (tmp_path / "empty.jsonl").write_text("")
    with pytest.raises(ValueError, match="empty.jsonl: no episode summaries"):
        plot_sweep(tmp_path / "empty.jsonl", tmp_path / "o")
    with pytest.raises(ValueError, match="no episode summaries"):
        plot_sweep([], tmp_path / "o")
    with pytest.raises(ValueError, match="lacks"):
        plot_sweep([{"seed": 1, "success": True}], tmp_path / "o")
    assert not (tmp_path / "o").exists()  # nothing written on a failed call


def test_plot_command_reports_errors_in_one_line(tmp_path, capsys):
    assert main(["plot", str(tmp_path / "missing"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("dodt-nav: error: ") and "missing" in err and len(err.strip().splitlines()) == 1
    assert main(["plot"]) == 2
