"""What a study leaves behind: ``results.csv`` (one row per run and update session),
``summary.md`` (per method and grid point, the mean and a 95 % confidence interval of every
metric over the runs) and box plots of OPDF, precision, recall and ghosts by method
(``fig_<metric>.png``, and the four side by side in ``fig_overview.png``).

``summarise(DIR)`` builds them from whatever runs of ``DIR`` have finished
(``mapupdate sweep --summarise DIR``); every file is written atomically.
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
from pathlib import Path

import numpy as np

from gridmap import FREE, OCCUPIED, MapUpdatingError, load_map
from gridmap.atomic import write_atomically, write_with
from gridmap.files import FileInputError, read_text
from scenarios.report import _pyplot


class StudyFolderError(MapUpdatingError, ValueError):
    """A folder that holds no study to summarise."""


# The columns of results.csv after scenario, seed, method, session and before the grid keys.
METRICS = ("opdf", "precision", "recall", "ghosts", "g_freed", "ape_rmse", "wall_s", "f1",
           "recall_all", "changes", "targets", "opdf_previous", "opdf_oracle", "cc", "ms",
           "scans_processed", "updater_cpu_s", "updater_state_mb")
# What summary.md reports, with how many decimals.
SUMMARY = {"opdf": 2, "precision": 3, "recall": 3, "f1": 3, "ghosts": 1, "g_freed": 1,
           "changes": 0, "ape_rmse": 3, "wall_s": 1}
FIGURES = ("opdf", "precision", "recall", "ghosts")
KEY_COLUMNS = ("scenario", "seed", "method", "session")


def _g_freed(run_dir: Path, previous: str, name: str) -> int:
    """Cells occupied in G_i that the method freed (free in M_i, not in M_{i-1})."""
    maps = run_dir / "maps"
    prev, upd = load_map(maps / f"M_{previous}.yaml").data, load_map(maps / f"M_{name}.yaml").data
    truth = load_map(maps / f"G_{name}.yaml").data
    return int(((truth == OCCUPIED) & (upd == FREE) & (prev != FREE)).sum())


def session_rows(run_dir, metrics: dict, wall: dict) -> list[dict]:
    """One row per update session of a finished run in ``run_dir`` (its ``metrics.json`` as
    ``metrics``); ``wall``: [s] per session name."""
    rows = []
    sessions = metrics["sessions"]
    for prev, s in zip(sessions, sessions[1:]):
        cd, mm, r = s["change_detection"], s["map_metrics"], s["resources"]
        upd = mm["updated_vs_truth"]
        rows.append({
            "scenario": metrics["scenario"], "seed": metrics["seed"],
            "method": metrics.get("method", "paper"), "session": s["name"],
            "opdf": upd["opdf"], "precision": cd["precision"], "recall": cd["recall"],
            "ghosts": s["ghost_cells"], "g_freed": _g_freed(Path(run_dir), prev["name"],
                                                            s["name"]),
            "ape_rmse": s["localization"]["previous_map"]["rmse"],
            "wall_s": wall.get(s["name"]), "f1": cd["f1"], "recall_all": cd["recall_all"],
            "changes": cd["changes"], "targets": cd["target_cells"],
            "opdf_previous": mm["previous_vs_truth"]["opdf"],
            "opdf_oracle": mm["oracle_vs_truth"]["opdf"], "cc": upd["cc"], "ms": upd["ms"],
            "scans_processed": r["scans_processed"], "updater_cpu_s": r["updater_cpu_s"],
            "updater_state_mb": r["updater_state_bytes"] / 1e6})
    return rows


# --- reading a study folder --------------------------------------------------------------------
RUN_KEY_CHARS = "A-Za-z0-9_.=+-"                 # what a sweep names its runs with
RUN_KEY = re.compile(f"[{RUN_KEY_CHARS}]+")


def collect(out_dir) -> tuple[list[dict], list[str]]:
    """(rows of every finished run in the study's order, the grid keys)."""
    out_dir = Path(out_dir)
    sweep = _json(out_dir / "sweep.json", "study file", missing="not a study folder")
    try:
        grid, keys = list(sweep["spec"].get("grid", {})), list(sweep["runs"])
    except (KeyError, TypeError, AttributeError) as e:
        raise StudyFolderError(f"{out_dir / 'sweep.json'}: not a study file of this project "
                               f"({type(e).__name__}: {e})") from None
    rows, study = [], out_dir.resolve()
    for key in keys:
        # a run's folder is one name inside runs/: never a path that leaves the study
        if not isinstance(key, str) or not RUN_KEY.fullmatch(key) or ".." in key:
            raise StudyFolderError(f"{out_dir / 'sweep.json'}: run {key!r} is not a run name "
                                   "of this study")
        folder = out_dir / "runs" / key
        # nor one that a link leads out of it (runs/a -> ../../elsewhere), links and .. resolved
        if not folder.resolve().is_relative_to(study):
            raise StudyFolderError(f"{folder}: the run's folder leads out of the study, to "
                                   f"{folder.resolve()}; a study's runs are folders of its own")
        path = folder / "result.json"
        if not path.exists():
            continue
        record = _json(path, "run result")
        try:
            point = record["run"].get("point", {})
            rows += [{**row, **{k: point.get(k) for k in grid}} for row in record["rows"]]
        except (KeyError, TypeError, AttributeError) as e:
            raise StudyFolderError(f"{path}: not a run result of this project "
                                   f"({type(e).__name__}: {e}); remove the run's folder to "
                                   "run it again") from None
    return rows, grid


def _json(path: Path, what: str, missing: str = "missing") -> dict:
    try:
        # read_text: a FIFO or a device put in a study's place is refused, not read forever
        data = json.loads(read_text(path, what))
    except FileNotFoundError:
        raise StudyFolderError(f"{path.parent}: {missing} (no {path.name})") from None
    except FileInputError as e:
        raise StudyFolderError(str(e)) from None
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as e:
        raise StudyFolderError(f"{path}: unreadable {what} ({type(e).__name__}: "
                               f"{' '.join(str(e).split())[:160]})") from None
    if not isinstance(data, dict):
        raise StudyFolderError(f"{path}: not a {what} (a JSON object was expected)")
    return data


def results_csv(rows: list[dict], grid: list[str]) -> str:
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=[*KEY_COLUMNS, *METRICS, *grid],
                            lineterminator="\n", extrasaction="ignore")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if v is None else v) for k, v in row.items()})
    return buf.getvalue()


# --- the summary --------------------------------------------------------------------------------
def mean_ci(values) -> tuple[float | None, float | None, int]:
    """(mean, half-width of the 95 % confidence interval (Student's t), n) of the values that
    exist; None where there are too few."""
    from scipy import stats

    v = np.array([x for x in values if x is not None and math.isfinite(x)], float)
    if v.size == 0:
        return None, None, 0
    if v.size == 1:
        return float(v[0]), None, 1
    half = stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size)
    return float(v.mean()), float(half), int(v.size)


def _groups(rows: list[dict], grid: list[str]) -> dict:
    """(method, grid values) -> run -> that run's rows, in the order first met."""
    out: dict = {}
    for row in rows:
        group = (row["method"], tuple(row.get(k) for k in grid))
        run = (row["scenario"], row["seed"])
        out.setdefault(group, {}).setdefault(run, []).append(row)
    return out


def run_means(runs: dict, metric: str) -> list[float | None]:
    """Per run, the mean of ``metric`` over its update sessions (None if it has none)."""
    out = []
    for rows in runs.values():
        v = [r[metric] for r in rows if r.get(metric) is not None]
        out.append(float(np.mean(v)) if v else None)
    return out


def _cell(mean, half, digits: int) -> str:
    if mean is None:
        return "n/a"
    return f"{mean:.{digits}f}" + ("" if half is None else f" ± {half:.{digits}f}")


def summary_markdown(rows: list[dict], grid: list[str]) -> str:
    groups = _groups(rows, grid)
    head = ["method", *grid, "runs", *SUMMARY]
    n_runs = sum(len(runs) for runs in groups.values())
    out = ["# Study summary", "",
           f"{len(rows)} session rows of {n_runs} finished runs. Per method and grid point: the mean over the runs of each run's "
           "mean over its update sessions, ± the half-width of a 95 % confidence interval "
           "(Student's t over the runs). Precision is left out of a session that changed "
           "nothing (the method `none`).", "",
           "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for (method, values), runs in groups.items():
        cells = [method, *(str(v) for v in values), str(len(runs))]
        for metric, digits in SUMMARY.items():
            mean, half, _ = mean_ci(run_means(runs, metric))
            cells.append(_cell(mean, half, digits))
        out.append("| " + " | ".join(cells) + " |")
    return "\n".join(out) + "\n"


# --- figures --------------------------------------------------------------------------------------
def _boxes(ax, rows: list[dict], grid: list[str], metric: str) -> None:
    """One box per method and grid point over the runs' means of ``metric``."""
    labels, data = [], []
    for (method, values), runs in _groups(rows, grid).items():
        v = [x for x in run_means(runs, metric) if x is not None]
        labels.append(method + "".join(f"\n{k}={x}" for k, x in zip(grid, values)))
        data.append(v if v else [np.nan])
    ax.boxplot(data, tick_labels=labels, showmeans=True)
    ax.set_title(f"{metric} per run (mean over its update sessions)", fontsize=9)
    ax.grid(axis="y", alpha=0.3)


def box_plot(rows: list[dict], grid: list[str], metrics, path: Path) -> None:
    """fig_<metric>.png for one metric, or side by side for several."""
    plt = _pyplot()
    metrics = [metrics] if isinstance(metrics, str) else list(metrics)
    n_boxes = len(_groups(rows, grid))
    width = max(4.0, 1.2 * n_boxes + 1)
    fig, axes = plt.subplots(1, len(metrics), figsize=(width * len(metrics), 3.6),
                             squeeze=False)
    for ax, metric in zip(axes[0], metrics):
        _boxes(ax, rows, grid, metric)
    write_with(path, lambda f: fig.savefig(f, format="png", dpi=110, bbox_inches="tight"))
    plt.close(fig)


def summarise(out_dir) -> int:
    """Write results.csv, summary.md and fig_<metric>.png of the study in ``out_dir`` from its
    finished runs; returns how many runs had finished."""
    out_dir = Path(out_dir)
    rows, grid = collect(out_dir)
    write_atomically(out_dir / "results.csv", results_csv(rows, grid))
    write_atomically(out_dir / "summary.md", summary_markdown(rows, grid))
    if rows:
        for metric in FIGURES:
            box_plot(rows, grid, metric, out_dir / f"fig_{metric}.png")
        box_plot(rows, grid, FIGURES, out_dir / "fig_overview.png")
    return len({(r["scenario"], r["seed"], r["method"], tuple(r.get(k) for k in grid))
                for r in rows})
