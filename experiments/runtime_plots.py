"""The runtime table as a figure: one module a row, laid out like the paper's Table II (median bar,
p95 whisker, the paper's figure where given): an episode's runtime.png (experiments.episode_plots) and
the reproduction report's (experiments.reproduce)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.figures import new_figure, save_figure, show_message


def plot_runtime_table(rows, out_png, title: str | None = None, paper_label: str = "paper (Intel NUC)") -> Path:
    """Horizontal bars laid out like the paper's Table II: one module a row, top to bottom as given; the
    bar is the median, the whisker reaches the p95. ``rows``: [(module, median_ms, p95_ms), ...], each
    optionally with a 4th item, the paper's milliseconds (drawn as a diamond; None for none), or a dict
    {module: {"median_ms", "p95_ms"}} as ``experiments.bench_perception.run_runtime`` returns. Returns out_png."""
    return save_figure(runtime_table_figure(rows, title, paper_label), Path(out_png))


def runtime_table_figure(rows, title: str | None = None, paper_label: str = "paper (Intel NUC)"):
    """The figure ``plot_runtime_table`` saves (same arguments), not yet drawn. Its legend is a figure
    legend in a row of its own under the x label, outside the axes: it covers no bar, value label,
    tick label or title, however long the labels are."""
    if isinstance(rows, dict):
        rows = [(m, v["median_ms"], v["p95_ms"]) for m, v in rows.items()]
    rows = [tuple(r) for r in rows]
    if any(len(r) not in (3, 4) for r in rows):
        raise ValueError("plot_runtime_table: each row must be (module, median_ms, p95_ms[, paper_ms])")
    n = len(rows)
    if n == 0:
        fig, ax = new_figure((8, 2.2))
        show_message(ax, "no runtime rows")
        ax.set_title(title or "runtime per call", fontsize=9)
        return fig
    fig, ax = new_figure((8, max(2.2, 0.45 * n + 1.4) + 0.3))  # + the legend's row
    names = [str(r[0]) for r in rows]
    med = np.array([np.nan if r[1] is None else float(r[1]) for r in rows])
    p95 = np.array([np.nan if r[2] is None else float(r[2]) for r in rows])
    y = np.arange(n)
    ok = np.isfinite(med)
    whisk = np.where(np.isfinite(p95), np.maximum(p95 - med, 0.0), 0.0)
    ax.barh(y[ok], med[ok], height=0.6, color="tab:blue", alpha=0.8, label="median")
    ax.errorbar(med[ok], y[ok], xerr=[np.zeros(ok.sum()), whisk[ok]], fmt="none", ecolor="k", capsize=4, lw=1,
                label="p95")
    paper = [(i, r[3]) for i, r in enumerate(rows) if len(r) == 4 and r[3] is not None]
    if paper:
        ax.plot([p for _, p in paper], [i for i, _ in paper], "D", color="tab:orange", ms=6, mec="k",
                label=paper_label)
    xmax = float(np.nanmax(np.concatenate([med[ok], p95[np.isfinite(p95)], [p for _, p in paper], [1e-3]])))
    for i in range(n):
        txt = "no data" if not ok[i] else (f"{med[i]:.2f} / {p95[i]:.2f} ms" if np.isfinite(p95[i])
                                           else f"{med[i]:.2f} ms")
        x = max(med[i] if ok[i] else 0.0, p95[i] if np.isfinite(p95[i]) else 0.0)
        ax.text(x + 0.02 * xmax, i, txt, va="center", fontsize=7)
    ax.set_yticks(y, names, fontsize=8)
    ax.invert_yaxis()  # first row on top, as in a table
    ax.set_xlim(0, xmax * 1.3)
    ax.set_xlabel("milliseconds per call (bar: median, whisker: p95; labels: median / p95)")
    handles, labels = ax.get_legend_handles_labels()
    order = sorted(range(len(labels)), key=lambda i: {"median": 0, "p95": 1}.get(labels[i], 2))
    fig.legend([handles[i] for i in order], [labels[i] for i in order], loc="outside lower center",
               ncol=len(handles), fontsize=7, frameon=False)
    ax.set_title(title or "runtime per call, laid out like the paper's Table II", fontsize=9)
    return fig
