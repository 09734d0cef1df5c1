"""A long run's report: the section "Over the sessions" (means, least-squares trends, first and
last fifths) and fig_sessions.png, checked on metrics made by hand with known values; and
which figures a run writes (fig_metrics.png only up to 12 update sessions)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from scenarios.report import render_report, write_outputs

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
STATS = ("max", "mean", "median", "min", "rmse", "std")


def _maps(opdf):
    return {"cc": 90.0, "ms": 80.0, "opdf": opdf}


def fake_session(name, precision, recall, opdf, oracle, ghosts):
    """One update session's entry of metrics.json, with what render_report reads."""
    return {
        "name": name,
        "map_metrics": {"previous_vs_truth": _maps(90.0), "updated_vs_truth": _maps(opdf),
                        "oracle_vs_truth": _maps(oracle)},
        "change_detection": {"precision": precision, "recall": recall, "f1": None,
                             "recall_all": None, "changes": 100, "target_cells": 50},
        "ghost_cells": ghosts,
        "localization": {"initial_map": dict.fromkeys(STATS, 0.02),
                         "previous_map": dict.fromkeys(STATS, 0.02)},
        "resources": {"scans": 10, "scans_processed": 5, "scans_dropped_as_lost": 0,
                      "updater_cpu_s": 1.0, "localizer_cpu_s": 1.0,
                      "updater_state_bytes": 1e6, "peak_rss_mb": 200.0, "simulated_s": 100.0},
    }


def fake_metrics(n, precision=None, recall=None, opdf=None, oracle=None, ghosts=None):
    """A run of a mapping session W1 and n update sessions W2 ... W(n+1). Each keyword is a
    list of n values (None allowed for precision and recall); the defaults are known lines."""
    precision = precision or [0.99 - 0.002 * i for i in range(n)]
    recall = recall or [0.80 + 0.001 * i for i in range(n)]
    opdf = opdf or [95.0 - 0.05 * i for i in range(n)]
    oracle = oracle or [97.0 for _ in range(n)]
    ghosts = ghosts or [i % 3 for i in range(n)]
    sessions = [{"name": "W1", "map_metrics": {}}]
    sessions += [fake_session(f"W{i + 2}", precision[i], recall[i], opdf[i], oracle[i],
                              ghosts[i]) for i in range(n)]
    return {"scenario": "fake", "seed": 5, "quick": True, "wall_time_s": 1.0,
            "sessions": sessions}


def slope(values):
    """Closed-form least-squares slope against the session's place (1, 2, ...), sessions
    without a value left out but keeping their places."""
    pts = [(i + 1, v) for i, v in enumerate(values) if v is not None]
    n = len(pts)
    sx = sum(x for x, _ in pts)
    sy = sum(y for _, y in pts)
    sxx = sum(x * x for x, _ in pts)
    sxy = sum(x * y for x, y in pts)
    return (n * sxy - sx * sy) / (n * sxx - sx * sx)


def avg(values):
    vals = [v for v in values if v is not None]
    return sum(vals) / len(vals)


def section(report):
    assert "## Over the sessions" in report
    return report.split("## Over the sessions", 1)[1].split("\n## ", 1)[0]


def row(report, label):
    """The cells of the section's row for one metric, keyed by column header."""
    lines = [ln for ln in section(report).splitlines() if ln.startswith("|")]
    header = [c.strip() for c in lines[0].strip("|").split("|")]
    for ln in lines[2:]:
        cells = [c.strip() for c in ln.strip("|").split("|")]
        if cells[0] == label:
            return dict(zip(header, cells))
    raise AssertionError(f"no row {label!r} in {lines}")


def cell(r, prefix):
    return next(v for k, v in r.items() if k.startswith(prefix))


def close(text, expected, digits):
    """The printed number equals expected to the digits it was printed with."""
    return abs(float(text) - expected) <= 0.5 * 10 ** -digits + 1e-12


# irregular values, with gaps, so a slope that ignored the gaps' places or the values'
# scatter would come out different
PRECISION = [0.97, None, 0.91, 0.99, None, 0.88, 0.95, 0.90, 0.86, 0.93, 0.84, 0.89]
RECALL = [0.70, 0.74, 0.69, None, 0.80, 0.83, 0.79, 0.86, 0.88, 0.85, 0.91, 0.90]
OPDF = [96.1, 95.4, 95.9, 95.0, 94.2, 94.8, 93.7, 94.0, 93.1, 92.6, 93.4, 92.0]
ORACLE = [97.5, 97.0, 97.8, 97.1, 96.9, 97.3, 96.5, 96.8, 96.2, 96.6, 96.0, 96.4]


@pytest.fixture(scope="module")
def twelve():
    return render_report(fake_metrics(12, PRECISION, RECALL, OPDF, ORACLE))


@pytest.mark.parametrize("label, values, digits", [
    ("precision", PRECISION, 5), ("recall", RECALL, 5),
    ("OPDF % of M(i)", OPDF, 4), ("OPDF % of the oracle", ORACLE, 4)])
def test_the_trend_is_the_least_squares_slope_per_session(twelve, label, values, digits):
    printed = cell(row(twelve, label), "trend")
    assert close(printed, slope(values), digits), (printed, slope(values))


def test_the_trend_of_a_straight_line_is_its_step():
    report = render_report(fake_metrics(20))
    assert row(report, "precision")["trend per session"] == "-0.00200"
    assert row(report, "recall")["trend per session"] == "+0.00100"
    assert row(report, "OPDF % of M(i)")["trend per session"] == "-0.0500"
    assert row(report, "OPDF % of the oracle")["trend per session"] == "+0.0000"


def test_the_fifths_are_the_first_and_last_fifth_of_the_sessions(twelve):
    # 12 sessions: a fifth is 2 (W2-W3 and W12-W13); precision has a gap in W3
    r = row(twelve, "precision")
    assert "first fifth (W2-W3)" in r and "last fifth (W12-W13)" in r
    assert close(r["first fifth (W2-W3)"], 0.97, 3)
    assert close(r["last fifth (W12-W13)"], avg(PRECISION[-2:]), 3)
    r = row(twelve, "OPDF % of M(i)")
    assert close(r["first fifth (W2-W3)"], avg(OPDF[:2]), 2)
    assert close(r["last fifth (W12-W13)"], avg(OPDF[-2:]), 2)


@pytest.mark.parametrize("n, k", [(5, 1), (9, 1), (10, 2), (40, 8), (100, 20)])
def test_a_fifth_is_at_least_one_session(n, k):
    opdf = [90.0 + i for i in range(n)]
    r = row(render_report(fake_metrics(n, opdf=opdf)), "OPDF % of M(i)")
    first = cell(r, "first fifth")
    last = cell(r, "last fifth")
    assert close(first, avg(opdf[:k]), 2) and close(last, avg(opdf[-k:]), 2)
    names = [f"W{i + 2}" for i in range(n)]
    span = names[0] if k == 1 else f"{names[0]}-{names[k - 1]}"
    assert f"first fifth ({span})" in r


def test_sessions_without_a_value_are_left_out(twelve):
    r = row(twelve, "precision")
    assert r["sessions with a value"] == "10"
    assert close(r["mean"], avg(PRECISION), 3)
    assert row(twelve, "recall")["sessions with a value"] == "11"
    assert close(row(twelve, "recall")["mean"], avg(RECALL), 3)


def test_a_metric_never_defined_reads_n_a():
    n = 6
    metrics = fake_metrics(n)
    for s in metrics["sessions"][1:]:
        s["change_detection"]["precision"] = None
    metrics["sessions"][3]["change_detection"]["recall"] = None
    r = row(render_report(metrics), "precision")
    assert r["sessions with a value"] == "0"
    assert {r["mean"], r["trend per session"], cell(r, "first"), cell(r, "last")} == {"n/a"}
    # one recall left out: the trend is that of the five left, still a straight line
    assert row(render_report(metrics), "recall")["trend per session"] == "+0.00100"


def test_the_section_starts_at_five_update_sessions():
    assert "## Over the sessions" not in render_report(fake_metrics(4))
    report = render_report(fake_metrics(5))
    assert "## Over the sessions" in report
    assert "least-squares" in section(report)


def _written(tmp_path, n):
    metrics = fake_metrics(n)
    out = tmp_path / f"run{n}"
    out.mkdir()
    write_outputs(SimpleNamespace(out_dir=out, metrics=metrics))
    return out, {p.name for p in out.iterdir()}


def _figures_line(out):
    return next(ln for ln in (out / "report.md").read_text().splitlines()
                if ln.startswith("Figures:"))


def test_a_short_run_keeps_fig_metrics_and_adds_fig_sessions(tmp_path):
    out, files = _written(tmp_path, 3)
    assert files == {"metrics.json", "report.md", "fig_metrics.png", "fig_sessions.png"}
    for name in ("fig_metrics.png", "fig_sessions.png"):
        assert (out / name).read_bytes()[:8] == PNG_MAGIC
        assert f"`{name}`" in _figures_line(out)


def test_a_long_run_writes_fig_sessions_only(tmp_path):
    out, files = _written(tmp_path, 40)
    assert files == {"metrics.json", "report.md", "fig_sessions.png"}
    assert (out / "fig_sessions.png").read_bytes()[:8] == PNG_MAGIC
    line = _figures_line(out)
    assert "`fig_sessions.png`" in line and "fig_metrics.png" not in line
    assert len(json.loads((out / "metrics.json").read_text())["sessions"]) == 41


def test_twelve_sessions_still_get_bars_and_thirteen_do_not(tmp_path):
    assert "fig_metrics.png" in _written(tmp_path, 12)[1]
    assert "fig_metrics.png" not in _written(tmp_path, 13)[1]


def test_gaps_in_precision_and_recall_are_drawn(tmp_path):
    metrics = fake_metrics(12, PRECISION, RECALL, OPDF, ORACLE)
    write_outputs(SimpleNamespace(out_dir=tmp_path, metrics=metrics))
    assert (tmp_path / "fig_sessions.png").read_bytes()[:8] == PNG_MAGIC


def test_a_run_without_update_sessions_writes_no_run_figure(tmp_path):
    metrics = fake_metrics(1)
    metrics["sessions"] = metrics["sessions"][:1]
    write_outputs(SimpleNamespace(out_dir=tmp_path, metrics=metrics))
    assert {p.name for p in tmp_path.iterdir()} == {"metrics.json", "report.md"}
