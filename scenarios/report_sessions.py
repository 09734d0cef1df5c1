"""What a run's report says over its update sessions: a table of means, trends and first
and last fifths in report.md, and fig_sessions.png, lines over the sessions.

Grouped bars per session (fig_metrics.png) stop being readable past a dozen sessions, and the
per-session tables of a run of 50 or 100 sessions hide whether the map gets better or worse;
these summaries answer that for runs of any length.
"""

from __future__ import annotations

import math

import numpy as np

# past this many update sessions fig_metrics.png's bars are too thin to read
MAX_BAR_SESSIONS = 12
# fewer sessions than this make a trend and two fifths of one session each say little
MIN_TREND_SESSIONS = 5
MAX_TICK_LABELS = 12

# (key in the series, label in the table, digits)
ROWS = (("precision", "precision", 3), ("recall", "recall", 3),
        ("opdf", "OPDF % of M(i)", 2), ("oracle_opdf", "OPDF % of the oracle", 2))
# fig_sessions.png's panels, top to bottom: (title, ((key in the series, legend), ...))
PANELS = (("Change detection", (("precision", "precision"), ("recall", "recall"))),
          ("OPDF % against G(i)", (("opdf", "M(i)"), ("oracle_opdf", "oracle"))),
          ("Ghost cells", (("ghosts", "M(i)"),)))


def update_sessions(metrics: dict) -> list[dict]:
    return [s for s in metrics["sessions"] if "change_detection" in s]


def run_figures(metrics: dict) -> list[str]:
    """The run-wide figures ``write_outputs`` writes, in the order the report names them."""
    n = len(update_sessions(metrics))
    if n == 0:
        return []
    return (["fig_metrics.png"] if n <= MAX_BAR_SESSIONS else []) + ["fig_sessions.png"]


def session_series(sessions: list[dict]) -> dict[str, list]:
    """Each plotted or tabled value, one entry per update session, None where undefined."""
    return {
        "precision": [s["change_detection"]["precision"] for s in sessions],
        "recall": [s["change_detection"]["recall"] for s in sessions],
        "opdf": [s["map_metrics"]["updated_vs_truth"]["opdf"] for s in sessions],
        "oracle_opdf": [s["map_metrics"]["oracle_vs_truth"]["opdf"] for s in sessions],
        "ghosts": [s["ghost_cells"] for s in sessions],
    }


def _defined(values: list) -> tuple[np.ndarray, np.ndarray]:
    """The session indices (1 for the first update session) that have a value, and the values:
    a session that is undefined keeps its place on the axis, so the slope stays per session."""
    pairs = [(i + 1, v) for i, v in enumerate(values)
             if v is not None and not (isinstance(v, float) and math.isnan(v))]
    return (np.array([p[0] for p in pairs], dtype=float),
            np.array([p[1] for p in pairs], dtype=float))


def mean(values: list) -> float | None:
    _, y = _defined(values)
    return float(y.mean()) if len(y) else None


def trend(values: list) -> float | None:
    """The least-squares slope of the values against the session index, per session."""
    x, y = _defined(values)
    if len(x) < 2:
        return None
    return float(np.polyfit(x, y, 1)[0])


def fifth(n: int) -> int:
    """How many sessions make a fifth of n: at least one."""
    return max(1, n // 5)


def fifth_means(values: list) -> tuple[float | None, float | None]:
    k = fifth(len(values))
    return mean(values[:k]), mean(values[-k:])


def _span(names: list[str]) -> str:
    return names[0] if len(names) == 1 else f"{names[0]}-{names[-1]}"


def _cell(v: float | None, digits: int, sign: bool = False) -> str:
    if v is None:
        return "n/a"
    # adding 0.0 turns a -0.0 from rounding into 0.0: a flat trend should not read "-0.000"
    return f"{round(v, digits) + 0.0:{'+' if sign else ''}.{digits}f}"


def over_the_sessions(sessions: list[dict]) -> list[str]:
    """report.md's section "Over the sessions", or nothing for a run too short for it."""
    if len(sessions) < MIN_TREND_SESSIONS:
        return []
    names = [s["name"] for s in sessions]
    k = fifth(len(names))
    series = session_series(sessions)
    out = ["## Over the sessions", "",
           f"Over the {len(names)} update sessions ({_span(names)}). Trend: the slope of the "
           "least-squares line through a metric's values against the session's index, in the "
           "metric's unit per session; a session where the metric is undefined (n/a in the "
           "tables: precision with no change made, recall with no target) is left out of its "
           "mean, trend and fifths.", "",
           f"| metric | sessions with a value | mean | trend per session | first fifth "
           f"({_span(names[:k])}) | last fifth ({_span(names[-k:])}) |",
           "|---|---|---|---|---|---|"]
    for key, label, digits in ROWS:
        values = series[key]
        first, last = fifth_means(values)
        out.append(f"| {label} | {len(_defined(values)[0])} | {_cell(mean(values), digits)} | "
                   f"{_cell(trend(values), digits + 2, sign=True)} | {_cell(first, digits)} | "
                   f"{_cell(last, digits)} |")
    return out + [""]


def _nan_for_none(values: list) -> np.ndarray:
    # NaN breaks a matplotlib line, which leaves the gap an undefined session should show
    return np.array([np.nan if v is None else v for v in values], dtype=float)


def draw_sessions_figure(plt, sessions: list[dict]):
    """fig_sessions.png's figure: precision and recall, OPDF of M(i) and of the oracle, and
    ghost cells, each a line over the update sessions."""
    # matplotlib is the [sim] extra's: imported when a figure is drawn, as report._pyplot does
    from matplotlib.ticker import MaxNLocator

    series = session_series(sessions)
    names = [s["name"] for s in sessions]
    x = np.arange(len(names))
    fig, axes = plt.subplots(3, 1, figsize=(10, 8), sharex=True)
    for ax, (title, lines) in zip(axes, PANELS):
        for key, label in lines:
            # markers, so a session between two undefined ones still shows
            ax.plot(x, _nan_for_none(series[key]), label=label, marker=".", markersize=4, lw=1)
        ax.set_title(title, fontsize=10)
        ax.grid(alpha=0.3)
        if len(lines) > 1:
            ax.legend(fontsize=8, loc="best")
    axes[-1].yaxis.set_major_locator(MaxNLocator(integer=True))    # ghosts are whole cells
    step = math.ceil(len(names) / MAX_TICK_LABELS)
    axes[-1].set_xticks(x[::step], names[::step])
    axes[-1].set_xlabel("update session")
    fig.tight_layout()
    return fig
