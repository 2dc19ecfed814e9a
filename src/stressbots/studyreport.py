"""The HTML report of a study (``DIR/report.html``): one self-contained page, pictures inline.

Success-rate curves with 95 % Wilson bands against every grid axis that has more than one value (one
curve per combination of the other conditions when there are few, else pooled over them), and a table
of every cell with its rate, interval and failure reasons. Built from the study's ``summary.json``
alone (:func:`build_study_report`), so a report can be redrawn from a finished or resumed store.
"""

from __future__ import annotations

import json
from collections import defaultdict
from collections.abc import Mapping, Sequence
from typing import Any

from .montecarlo import wilson_interval

__all__ = ["success_curves", "plot_axis", "failure_chart", "build_study_report", "MAX_SERIES"]

MAX_SERIES = 8
"""At most this many curves per picture; with more combinations of the other conditions, they are pooled."""


def _key(v: Any) -> str:
    return json.dumps(v, sort_keys=True)


def success_curves(summary: Mapping[str, Any], axis: str) -> tuple[list[Any], dict[str, list[tuple[int, int]]]]:
    """Values of ``axis`` and, per series (a combination of the other conditions, or ``"all"`` pooled),
    ``(successes, trials)`` at each value."""
    values = list(summary["axes"][axis])
    others = [k for k in ["layout", *summary["axes"]] if k != axis]
    combos: dict[str, dict[str, list[int]]] = defaultdict(lambda: defaultdict(lambda: [0, 0]))
    for row in summary["cells"]:
        cond = {"layout": row["layout"], **row["params"]}
        name = ", ".join(f"{k}={cond[k]}" for k in others if k in cond and (k != "layout" or len(summary["layouts"]) > 1)) or "all"
        acc = combos[name][_key(cond[axis])]
        acc[0] += row["successes"]
        acc[1] += row["trials"]
    if len(combos) > MAX_SERIES:
        pooled: dict[str, list[int]] = defaultdict(lambda: [0, 0])
        for series in combos.values():
            for v, (s, n) in series.items():
                pooled[v][0] += s
                pooled[v][1] += n
        combos = {"all (pooled over the other conditions)": pooled}
    return values, {name: [(c[0], c[1]) for c in (series.get(_key(v), [0, 0]) for v in values)] for name, series in combos.items()}


def plot_axis(summary: Mapping[str, Any], axis: str):
    """Success rate against one grid axis, with the Wilson 95 % band of every curve."""
    from .viz import _plt

    plt = _plt()
    values, series = success_curves(summary, axis)
    numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values)
    x = [float(v) for v in values] if numeric else list(range(len(values)))
    fig, ax = plt.subplots(figsize=(7, 4))
    alpha = 0.2 / len(series) ** 0.5  # overlapping bands stay readable
    for name, counts in series.items():
        rate = [s / n if n else float("nan") for s, n in counts]
        band = [wilson_interval(s, n) for s, n in counts]
        order = sorted(range(len(x)), key=lambda i: x[i])
        xs = [x[i] for i in order]
        line, = ax.plot(xs, [rate[i] for i in order], marker="o", label=name)
        ax.fill_between(xs, [band[i][0] for i in order], [band[i][1] for i in order], color=line.get_color(), alpha=alpha, linewidth=0)
    if not numeric:
        ax.set_xticks(x, [str(v) for v in values])
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel(axis)
    ax.set_ylabel("success rate")
    ax.grid(alpha=0.3)
    ax.set_title(f"success rate vs {axis} ({summary['trials_per_cell']} paired trials per cell; bands: Wilson 95 %)", fontsize=9)
    ax.legend(fontsize=7, loc="best")
    return fig


def _layout_chart(summary: Mapping[str, Any]):
    """Success rate per cell with Wilson intervals (when no grid axis varies, or as an overview)."""
    from .viz import _plt

    plt = _plt()
    rows = summary["cells"]
    fig, ax = plt.subplots(figsize=(7, 0.35 * len(rows) + 1.2))
    y = list(range(len(rows)))[::-1]
    rate = [r["success_rate"] for r in rows]
    lo = [r["success_rate"] - r["success_rate_ci95"][0] for r in rows]
    hi = [r["success_rate_ci95"][1] - r["success_rate"] for r in rows]
    ax.errorbar(rate, y, xerr=[lo, hi], fmt="o", capsize=3)
    ax.set_yticks(y, [r["label"] for r in rows], fontsize=7)
    ax.set_xlim(-0.02, 1.02)
    ax.set_xlabel("success rate (Wilson 95 %)")
    ax.grid(alpha=0.3, axis="x")
    return fig


def failure_chart(summary: Mapping[str, Any], top: int = 6):
    """Failure reasons per cell, stacked (the ``top`` most common kinds; the rest as "other")."""
    from .viz import _plt

    plt = _plt()
    rows = summary["cells"]
    totals: dict[str, int] = defaultdict(int)
    for r in rows:
        for kind, n in r["failures"].items():
            totals[kind] += n
    kinds = [k for k, _ in sorted(totals.items(), key=lambda kv: (-kv[1], kv[0]))[:top]]
    fig, ax = plt.subplots(figsize=(8, 0.35 * len(rows) + 1.6))
    y = list(range(len(rows)))[::-1]
    left = [0.0] * len(rows)
    for kind in kinds + ["other"]:
        w = [(r["failures"].get(kind, 0) if kind != "other"
              else sum(n for k, n in r["failures"].items() if k not in kinds)) / max(r["trials"], 1)
             for r in rows]
        if any(w):
            ax.barh(y, w, left=left, label=kind[:70])
            left = [a + b for a, b in zip(left, w, strict=True)]
    ax.set_yticks(y, [r["label"] for r in rows], fontsize=7)
    ax.set_xlim(0, 1)
    ax.set_xlabel("fraction of the cell's trials")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.12 - 0.6 / max(len(rows), 1)), ncol=1)
    ax.set_title("failure reasons per cell", fontsize=9)
    return fig


def build_study_report(summary: Mapping[str, Any]) -> str:
    """The report page (HTML text) of a study summary."""
    from .outputs import figure_bytes
    from .report import _e, _kv, _page, _table, png_data_uri

    def img(fig, alt: str) -> str:
        return f'<img src="{png_data_uri(figure_bytes(fig))}" alt="{_e(alt)}">'

    varying = [k for k, v in summary["axes"].items() if len(v) > 1]
    curves = "".join(f"<h3>{_e(k)}</h3>{img(plot_axis(summary, k), f'success rate vs {k}')}" for k in varying)
    overview = img(_layout_chart(summary), "success rate per cell")
    fails = img(failure_chart(summary),
                "failure reasons per cell") if any(r["failures"] for r in summary["cells"]) else "<p>No failures.</p>"
    table_rows = []
    for r in summary["cells"]:
        lo, hi = r["success_rate_ci95"]
        reasons = "; ".join(f"{n} x {_e(k)}" for k, n in list(r["failures"].items())[:4]) or "-"
        if r.get("plan_error"):
            reasons = f"no nominal plan: {_e(r['plan_error'])}"
        pv = r.get("paired_vs_baseline")
        paired = "baseline" if pv is None else f"+{pv['gained']} / -{pv['lost']} vs cell {pv['baseline_cell']} (p = {pv['mcnemar_p']:.2g})"
        table_rows.append([str(r["cell"]), _e(r["layout"]), _e(", ".join(f"{k}={v}" for k, v in r["params"].items()) or "-"),
                           f"{r['successes']}/{r['trials']}", f"{r['success_rate']:.3f}", f"{lo:.3f}-{hi:.3f}", paired, reasons])
    cells = _table(["cell", "layout", "conditions", "successes", "rate", "95 % CI", "paired (McNemar)", "failure reasons"], table_rows,
                   left=(1, 2, 6, 7))
    cells = ('<p class="note">Paired: trials that succeed in this cell but not in the first cell of its layout (+), the reverse '
             '(-), over the same seeds, with the exact McNemar test\'s two-sided p-value.</p>' + cells)
    lo, hi = summary["success_rate_ci95"]
    facts = _kv([
        ("trials", f"{summary['trials']} ({summary['trials_per_cell']} per cell, {len(summary['cells'])} cells)"),
        ("successes", f"{summary['successes']} (rate {summary['success_rate']:.3f}, 95 % CI {lo:.3f}-{hi:.3f})"),
        ("seed", f"{summary['seed']} (paired: trial k of every cell has the same plant seed)"),
        ("layouts", _e(", ".join(f"{lay['label']} ({lay['robots']} robots; {lay['source']})" for lay in summary["layouts"]))),
        ("grid", _e("; ".join(f"{k} = {v}" for k, v in summary["axes"].items()) or "-")),
        ("fixed", _e("; ".join(f"{k} = {v}" for k, v in summary["fixed"].items()) or "-")),
        ("versions", _e(", ".join(f"{k} {v}" for k, v in summary.get("provenance", {}).get("versions", {}).items()))),
    ])
    body = (f'<section id="study"><h2>Study</h2>{facts}</section>'
            f'<section id="curves"><h2>Success rate</h2><p class="note">Shaded bands and error bars: 95 % Wilson score '
            f'intervals of each cell&#39;s success rate. Cells share their trial seeds (paired), so a difference between two '
            f'cells comes from the conditions, not from different draws.</p>{curves}<h3>every cell</h3>{overview}</section>'
            f'<section id="failures"><h2>Failure reasons</h2>{fails}</section>'
            f'<section id="cells"><h2>Cells</h2>{cells}</section>')
    nav: Sequence[tuple[str, str]] = (("study", "Study"), ("curves", "Success rate"), ("failures", "Failures"), ("cells", "Cells"))
    return _page(f"Study: {summary['name']}", f"{summary['trials']} closed-loop trials on the simulated plant", body, nav=nav)
