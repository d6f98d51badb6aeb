"""Seed-by-seed comparison of two sweeps: did a change make the closed loop better, worse, or neither?

Two sweeps over the same seeds of a scenario (a baseline and a change) are paired seed by seed. The
outcome of one corridor episode turns on small things (a replan 0.1 s apart, a track one frame
older), so any change of the planner or the perception turns some seeds each way; the two success
rates alone cannot tell a real gain from that churn. The paired question can: among the
seeds whose outcome differs, are those turned to success more than a fair coin would give? That is
McNemar's exact test, a two-sided sign test on the discordant seeds; seeds with the same outcome in
both sweeps say nothing about the change and do not enter it. The verdict is the success's; every
outcome class (at-fault collision, timeout, ...) gets the same paired test beside its counts, so that
a change that trades at-fault collisions for timeouts shows it, and a 95 % interval of the change in
its rate (Newcombe's paired score interval, ``paired_interval``).

A sweep folder is what ``dodt-nav sweep --out`` writes; only its ``results.jsonl`` is read.
"""
from __future__ import annotations

import math
import statistics
from dataclasses import dataclass, field
from pathlib import Path

from experiments.environment import differences, distinct
from experiments.sweep import RESULTS, SweepError, read_results, wilson


# (row label, results field) of each outcome class compared seed by seed
_OUTCOMES = (("success", "success"), ("at-fault collision", "at_fault"),
             ("only not-at-fault collisions", "not_at_fault_only"), ("collision", "collided"), ("timeout", "timeout"))


class CompareError(ValueError):
    """The two sweeps cannot be compared (a folder without results, no seed in common)."""


@dataclass(frozen=True)
class SweepComparison:
    base: str
    new: str
    seeds: tuple[int, ...]  # run in both sweeps
    base_success: int
    new_success: int
    to_success: tuple[int, ...]  # failed in the baseline, succeeded with the change
    to_failure: tuple[tuple[int, str], ...]  # (seed, the change's failure reason)
    p_value: float  # two-sided exact sign test on the discordant seeds
    counts: dict  # {"at-fault collision": (base, new), ..., "collision": ..., "timeout": ...}
    median_speed: tuple[float | None, float | None]  # of the successful episodes, m/s
    only_in_base: int = 0
    only_in_new: int = 0
    warnings: tuple[str, ...] = field(default_factory=tuple)
    # per outcome class of counts, and "success", paired: (seeds with it in the baseline only, in the
    # change only, the sign test's p on those, paired_interval's (difference, low, high) of its rate)
    changes: dict = field(default_factory=dict)

    @property
    def verdict(self) -> str:
        return verdict(len(self.to_success), len(self.to_failure), self.p_value)


def sign_test_p(k: int, n: int) -> float:
    """Two-sided exact binomial test of k successes in n fair trials (scipy's binomtest; 1 when n = 0)."""
    if not 0 <= k <= n:
        raise ValueError(f"k must lie in [0, n], got k={k}, n={n}")
    if n == 0:
        return 1.0
    from scipy.stats import binomtest  # half a second to import: only when a test is made

    return float(binomtest(k, n, 0.5).pvalue)


def paired_interval(both: int, only_new: int, only_base: int, neither: int,
                    confidence: float = 0.95) -> tuple[float, float, float]:
    """(difference, low, high): the change's rate of an outcome less the baseline's, over paired seeds
    (``both``: seeds with the outcome in both sweeps, ``only_new`` / ``only_base``: in one, ``neither``),
    with Newcombe's score interval for paired proportions (Statistics in Medicine 17, 1998, method 10):
    each sweep's Wilson interval, combined with the correlation of the pairs."""
    n = both + only_new + only_base + neither
    if n == 0:
        return 0.0, -1.0, 1.0
    p1, p2 = (both + only_new) / n, (both + only_base) / n
    l1, u1 = wilson(both + only_new, n, confidence)
    l2, u2 = wilson(both + only_base, n, confidence)
    margins = (both + only_new) * (only_base + neither) * (both + only_base) * (only_new + neither)
    phi = 0.0
    if margins > 0:
        b = both * neither - only_new * only_base
        c = b - n / 2 if b > n / 2 else (b if b < 0 else 0.0)  # Newcombe's continuity correction
        phi = c / math.sqrt(margins)
    d = p1 - p2
    low = d - math.sqrt(max(0.0, (p1 - l1) ** 2 - 2 * phi * (p1 - l1) * (u2 - p2) + (u2 - p2) ** 2))
    high = d + math.sqrt(max(0.0, (p2 - l2) ** 2 - 2 * phi * (p2 - l2) * (u1 - p1) + (u1 - p1) ** 2))
    return d, max(-1.0, low), min(1.0, high)


def verdict(up: int, down: int, p: float, alpha: float = 0.05) -> str:
    if up == down == 0:
        return "no seed changed outcome"
    if p >= alpha:
        return f"no clear difference (p = {p:.3g} >= {alpha:g}: within the seed-to-seed churn)"
    return f"{'better' if up > down else 'worse'} (p = {p:.3g})"


def _load(folder: Path) -> dict[int, dict]:
    path = folder / RESULTS if folder.is_dir() else folder
    if not path.is_file():
        raise CompareError(f"{folder}: no {RESULTS} (a folder written by dodt-nav sweep --out, or the file itself)")
    try:
        rows = read_results(path)
    except SweepError as e:
        raise CompareError(str(e)) from None
    if not rows:
        raise CompareError(f"{path}: no finished episode in it")
    return rows


def _median_speed(rows) -> float | None:
    v = [float(r["mean_speed"]) for r in rows if r.get("success") and r.get("mean_speed") is not None]
    return round(statistics.median(v), 3) if v else None


def _environment_warnings(a: dict[int, dict], b: dict[int, dict], common: list[int]) -> list[str]:
    """Outcomes agree bit for bit only within one machine and installation: say when the two sweeps
    (or the episodes within one) ran in different ones."""
    out = []
    envs = {}
    for name, rows in (("baseline", a), ("change", b)):
        recorded = [rows[s].get("environment") for s in common]
        if not all(recorded):
            out.append(f"some episodes of the {name} record no environment (run before episodes recorded it): "
                       f"whether both sweeps ran on the same machine and installation is unknown")
        known = distinct(recorded)
        if len(known) > 1:
            out.append(f"the {name}'s episodes ran in {len(known)} environments ({'; '.join(differences(*known[:2]))})")
        envs[name] = known[0] if known else None
    if envs["baseline"] is not None and envs["change"] is not None:
        diff = differences(envs["baseline"], envs["change"])
        if diff:
            out.append("the sweeps ran in different environments (" + "; ".join(diff) + "): outcomes differ across "
                       "machines and installations by themselves, so the churn measured here is not the change's "
                       "alone; sweep the baseline again where the change ran")
    return out


def compare_sweeps(base: str | Path, new: str | Path) -> SweepComparison:
    """Pair the two sweeps' episodes by seed (sweep folders or results files)."""
    a, b = _load(Path(base)), _load(Path(new))
    common = sorted(set(a) & set(b))
    if not common:
        raise CompareError(f"{base} and {new} have no seed in common")
    warnings = []
    for key in ("scenario", "static_map", "frame_latency"):
        va, vb = {a[s].get(key) for s in common}, {b[s].get(key) for s in common}
        if va != vb:
            warnings.append(f"the sweeps differ in {key}: {sorted(map(str, va))} against {sorted(map(str, vb))}")
    warnings += _environment_warnings(a, b, common)
    ok_a = {s: bool(a[s].get("success")) for s in common}
    ok_b = {s: bool(b[s].get("success")) for s in common}
    up = tuple(s for s in common if ok_b[s] and not ok_a[s])
    down = tuple((s, str(b[s].get("failure_reason") or "failed")) for s in common if ok_a[s] and not ok_b[s])
    counts, changes = {}, {}
    for k, f in _OUTCOMES:
        has = lambda row: bool(row.get(f, row.get("collided") if f == "at_fault" else False))  # noqa: E731
        in_a, in_b = {s for s in common if has(a[s])}, {s for s in common if has(b[s])}
        if k != "success":
            counts[k] = (len(in_a), len(in_b))
        gone, new_ = len(in_a - in_b), len(in_b - in_a)
        changes[k] = (gone, new_, sign_test_p(gone, gone + new_),
                      paired_interval(len(in_a & in_b), new_, gone, len(common) - len(in_a | in_b)))
    return SweepComparison(
        base=str(base), new=str(new), seeds=tuple(common), base_success=sum(ok_a.values()),
        new_success=sum(ok_b.values()), to_success=up, to_failure=down,
        p_value=changes["success"][2], counts=counts,  # the sign test on the seeds turned either way
        median_speed=(_median_speed(a[s] for s in common), _median_speed(b[s] for s in common)),
        only_in_base=len(set(a) - set(b)), only_in_new=len(set(b) - set(a)), warnings=tuple(warnings),
        changes=changes)


def format_comparison(c: SweepComparison) -> str:
    n = len(c.seeds)
    pct = lambda k: f"{k} ({100.0 * k / n:.1f} %)"  # noqa: E731
    lines = [f"{n} seeds in both sweeps" + (f" ({c.only_in_base} only in the baseline, {c.only_in_new} only in the "
                                             f"change, left out)" if c.only_in_base or c.only_in_new else ""),
             "",
             "| | baseline | change | change - baseline [95 % interval] | seeds: baseline only / change only, "
             "sign test p |",
             "| --- | --- | --- | --- | --- |"]

    def cells(k):
        if k not in c.changes:
            return " | |"
        gone, new_, p, (d, lo, hi) = c.changes[k]
        return f" | {100 * d:+.1f} [{100 * lo:+.1f}, {100 * hi:+.1f}] points | {gone} / {new_}, p = {p:.3g} |"

    lines.append(f"| success | {pct(c.base_success)} | {pct(c.new_success)}" + cells("success"))
    for k, (x, y) in c.counts.items():
        lines.append(f"| {k} | {pct(x)} | {pct(y)}" + cells(k))
    fmt = lambda v: "-" if v is None else f"{v:.2f} m/s"  # noqa: E731
    lines += [f"| median speed of successes | {fmt(c.median_speed[0])} | {fmt(c.median_speed[1])} | | |", "",
              f"turned to success ({len(c.to_success)}): " + (", ".join(map(str, c.to_success)) or "none"),
              f"turned to failure ({len(c.to_failure)}): "
              + (", ".join(f"{s} ({why})" for s, why in c.to_failure) or "none"),
              f"sign test on the {len(c.to_success) + len(c.to_failure)} seeds that changed: two-sided p = "
              f"{c.p_value:.3g}",
              f"verdict: {c.verdict}"]
    lines += [f"warning: {w}" for w in c.warnings]
    return "\n".join(lines)


__all__ = ["CompareError", "SweepComparison", "compare_sweeps", "format_comparison", "paired_interval", "sign_test_p",
           "verdict"]
