"""Headless matplotlib figures: made and saved without pyplot.

Figures are ``matplotlib.figure.Figure`` objects rendered by the Agg canvas, never registered with
pyplot (no global backend switch, nothing left open after saving). The same input gives the same
PNG: the files carry no time stamp or software version.
"""
from __future__ import annotations

from pathlib import Path

DPI = 110  # as experiments.bench_perception
COLLISION_COLOR = "#ff0000"  # pure red is kept for collisions in every figure


def new_figure(figsize=(8, 5), nrows=1, ncols=1, **kw):
    """A pyplot-free figure (Agg canvas) and its axes."""
    try:
        from matplotlib.figure import Figure
    except ImportError:
        raise RuntimeError("matplotlib is not installed: no plots (pip install matplotlib)") from None
    fig = Figure(figsize=figsize, layout="constrained")
    ax = fig.subplots(nrows, ncols, **kw)
    return fig, ax


def save_figure(fig, path: Path, tight: bool = False) -> Path:
    """Writes ``fig`` as a PNG at ``path`` (``tight``: trimmed to what is drawn) and clears it; returns path."""
    try:
        kw = {"bbox_inches": "tight", "pad_inches": 0.1} if tight else {}
        fig.savefig(path, dpi=DPI, metadata={"Software": None}, **kw)
    finally:
        fig.clear()  # drop the artists at once; the figure is not known to pyplot
    return path


def show_message(ax, text: str) -> None:
    """An axes holding only ``text``: the figure that says why there is nothing to draw."""
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, fontsize=11, wrap=True)
    ax.set_xticks([])
    ax.set_yticks([])
