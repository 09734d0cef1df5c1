"""What a run leaves behind: maps, trajectories, metrics.json, report.md and figures.

A session's own files (its maps, TUM trajectories and two figures) are written as soon as it
ends; metrics.json, report.md and the summary figure at the end of the run. Every file is
written with ``gridmap.atomic`` (a temporary name, flushed, renamed), so a run killed halfway
never leaves a truncated map or report.
"""

from __future__ import annotations

import gc
import json
import os
import platform
from pathlib import Path

import numpy as np

from gridmap import FREE, OCCUPIED, OccupancyGrid, save_map
from gridmap.atomic import write_atomically, write_with
from robotlogs.tum import write_tum

from .report_sessions import (draw_sessions_figure, over_the_sessions, run_figures,
                              update_sessions)


def write_session_maps(out_dir: Path, result) -> None:
    """M_i and G_i of one session as map_server YAML + PGM."""
    maps = Path(out_dir) / "maps"
    maps.mkdir(parents=True, exist_ok=True)
    idx = result.name
    save_map(result.updated, maps / f"M_{idx}.yaml")
    save_map(result.truth, maps / f"G_{idx}.yaml")
    if result.oracle is not None:
        save_map(result.oracle, maps / f"oracle_{idx}.yaml")
    if result.masks:
        # per-cell evaluation masks, for anyone who wants to recompute or inspect the scores
        write_with(maps / f"masks_{idx}.npz", lambda f: np.savez_compressed(f, **result.masks))


def _fmt(v, digits=2) -> str:
    if v is None:
        return "n/a"
    return f"{v:.{digits}f}"


def machine_summary() -> str:
    return f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"


def _method_note(metrics: dict) -> str:
    # the paper's updater is the default: its reports read as they always did
    method = metrics.get("method", "paper")
    return "" if method == "paper" else f", method {method}"


def _profile_lines(metrics: dict) -> list[str]:
    """The profile the run's robot software started from and every key that differs from it;
    the paper profile's comparison, when there is one."""
    profile = metrics.get("profile")
    if profile is None:         # a run recorded before profiles
        return []
    out = [f"Profile `{profile}` (docs/configuration.md), pose check "
           f"{'on' if metrics.get('pose_check') else 'off'}."]
    diffs = metrics.get("differences") or []
    if diffs:
        out.append("Keys over the profile: " + "; ".join(f"`{d}`" for d in diffs) + " (the "
                   "localiser's alphas are the simulated robot's odometry noise).")
    if any("comparison" in s for s in metrics["sessions"]):
        out.append("The columns and rows marked *paper profile* are the paper profile's "
                   "updater fed the same scans at the same poses, from the same M(i-1), as a "
                   "comparison (`--profile paper` runs the paper's method throughout).")
    return out + [""]


def render_report(metrics: dict) -> str:
    """report.md: the paper's Tables I and II and the project's own tables."""
    sessions = [s for s in metrics["sessions"] if "change_detection" in s]
    out = [f"# Map updating on `{metrics['scenario']}`", "",
           f"Seed {metrics['seed']}{', quick routes' if metrics.get('quick') else ''}"
           f"{_method_note(metrics)}; "
           f"wall time {metrics['wall_time_s']:.1f} s on {machine_summary()}.", ""]
    out += _profile_lines(metrics)
    first = metrics["sessions"][0]
    if "initial_vs_truth" in first.get("map_metrics", {}):
        m = first["map_metrics"]["initial_vs_truth"]
        out += [f"M1 (built in {first['name']} by log-odds mapping) against G1: "
                f"CC {m['cc']:.2f} %, MS {m['ms']:.2f} %, OPDF {m['opdf']:.2f} %.", ""]
    if not sessions:
        return "\n".join(out) + "\n"
    # the paper profile's updater on the same scans and poses, beside the run's own
    compared = all("comparison" in s for s in sessions)
    # first, so a long run's report opens on where it went rather than on hundreds of rows
    out += over_the_sessions(sessions)
    out += _table_one(sessions, compared) + _table_two(sessions)
    out += _change_table(sessions, compared, metrics.get("profile") or "paper")
    out += _resources_table(sessions)
    out += ["", _figures_line(metrics), ""]
    return "\n".join(out)


def _figures_line(metrics: dict) -> str:
    about = {"fig_metrics.png": "`fig_metrics.png`",
             "fig_sessions.png": "`fig_sessions.png` (precision and recall, OPDF of M(i) and of "
                                 "the oracle, ghost cells, over the sessions)"}
    return ("Figures: `fig_maps_<session>.png` (M(i-1), M(i), G(i); removed cells red, added "
            "green), `fig_trajectories_<session>.png`, "
            + ", ".join(about[name] for name in run_figures(metrics)) + ".")


def _table_one(sessions, compared: bool) -> list[str]:
    other = " | M(i), paper profile" if compared else ""
    out = ["## Map quality (the paper's Table I)", "",
           f"| session | metric | M(i-1) vs G(i) | M(i) vs G(i){other} | oracle vs G(i) |",
           "|---|---|---|---|---|" + ("---|" if compared else "")]
    for s in sessions:
        mm = s["map_metrics"]
        for key, label in (("cc", "CC %"), ("ms", "MS %"), ("opdf", "OPDF %")):
            paper = f" | {_fmt(s['comparison']['map_metrics']['updated_vs_truth'][key])}" \
                if compared else ""
            out.append(f"| {s['name']} | {label} | {_fmt(mm['previous_vs_truth'][key])} | "
                       f"{_fmt(mm['updated_vs_truth'][key])}{paper} | "
                       f"{_fmt(mm['oracle_vs_truth'][key])} |")
    return out


def _table_two(sessions) -> list[str]:
    out = ["", "## Localisation, APE in metres (the paper's Table II)", "",
           "| session | map | max | mean | median | min | RMSE | std |",
           "|---|---|---|---|---|---|---|---|"]
    for s in sessions:
        for key, label in (("initial_map", "M1"), ("previous_map", "M(i-1)")):
            a = s["localization"][key]
            out.append(f"| {s['name']} | {label} | " + " | ".join(
                _fmt(a[k], 3) for k in ("max", "mean", "median", "min", "rmse", "std")) + " |")
    return out


def _change_table(sessions, compared: bool, profile: str) -> list[str]:
    out = ["", "## Change detection (one cell of slack)", "",
           "| session | profile | precision | recall | F1 | recall_all | changes | targets | "
           "ghosts |", "|---|---|---|---|---|---|---|---|---|"]
    for s in sessions:
        rows = [(profile, s["change_detection"], s["ghost_cells"])]
        if compared:
            c = s["comparison"]
            rows.append((c["profile"], c["change_detection"], c["ghost_cells"]))
        for name, cd, ghosts in rows:
            out.append(f"| {s['name']} | {name} | {_fmt(cd['precision'], 3)} | "
                       f"{_fmt(cd['recall'], 3)} | {_fmt(cd['f1'], 3)} | "
                       f"{_fmt(cd['recall_all'], 3)} | {cd['changes']} | {cd['target_cells']} | "
                       f"{ghosts} |")
    return out


def _resources_table(sessions) -> list[str]:
    out = ["", "## Resources", "",
           "| session | scans | processed | dropped as lost | updater CPU s | "
           "localiser CPU s | updater state MB | peak RSS MB | simulated s |",
           "|---|---|---|---|---|---|---|---|---|"]
    for s in sessions:
        r = s["resources"]
        out.append(f"| {s['name']} | {r['scans']} | {r['scans_processed']} | "
                   f"{r['scans_dropped_as_lost']} | {r['updater_cpu_s']:.2f} | "
                   f"{r['localizer_cpu_s']:.2f} | {r['updater_state_bytes'] / 1e6:.2f} | "
                   f"{r['peak_rss_mb']:.0f} | {r['simulated_s']:.0f} |")
    return out


def _map_rgb(grid: OccupancyGrid) -> np.ndarray:
    d = grid.data
    img = np.full(d.shape + (3,), 0.75)
    img[d == FREE] = 1.0
    img[d == OCCUPIED] = 0.0
    return img[::-1]   # row 0 is the lowest y: flip so north is up


def _save_fig(fig, path: Path) -> None:
    write_with(path, lambda f: fig.savefig(f, format="png", dpi=110, bbox_inches="tight"))


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def session_output_paths(out_dir: Path, name: str) -> list[Path]:
    """The files ``write_session_outputs`` writes for an update session: its three TUM
    trajectories (true, on M(i-1), on M1), then its two figures (maps, trajectories)."""
    out_dir = Path(out_dir)
    traj_dir = out_dir / "trajectories"
    return [traj_dir / f"{name}_true.tum", traj_dir / f"{name}_on_previous_map.tum",
            traj_dir / f"{name}_on_initial_map.tum", out_dir / f"fig_maps_{name}.png",
            out_dir / f"fig_trajectories_{name}.png"]


def write_session_trajectories(out_dir: Path, s) -> None:
    """An update session's trajectories in TUM format: true, on M(i-1), on M1."""
    if s.trajectory is None:
        return
    tr = s.trajectory.arrays()
    paths = session_output_paths(out_dir, s.name)[:3]
    paths[0].parent.mkdir(exist_ok=True)
    for path, key in zip(paths, ("true", "previous_map", "initial_map")):
        write_tum(path, tr["time"], tr[key])


def write_session_figures(out_dir: Path, s) -> None:
    """An update session's figures: M(i-1), M(i) (removed cells red, added green) and G(i);
    the trajectories on M(i). Needs the session's full result."""
    if s.previous is None:
        return
    plt = _pyplot()
    maps_png, trajectories_png = session_output_paths(out_dir, s.name)[3:]
    prev, upd = s.previous.data, s.updated.data
    img = _map_rgb(s.updated)
    removed = ((prev == OCCUPIED) & (upd == FREE))[::-1]
    added = ((prev != OCCUPIED) & (upd == OCCUPIED))[::-1]
    img[removed] = (0.9, 0.1, 0.1)
    img[added] = (0.1, 0.75, 0.1)
    fig, axes = plt.subplots(1, 3, figsize=(12, 6))
    for ax, im, title in zip(axes, (_map_rgb(s.previous), img, _map_rgb(s.truth)),
                             (f"M(i-1) before {s.name}", f"M(i) after {s.name}",
                              f"G(i) of {s.name}")):
        ax.imshow(im, interpolation="nearest")
        ax.set_title(title)
        ax.set_axis_off()
    _save_fig(fig, maps_png)
    plt.close(fig)

    tr = s.trajectory.arrays()
    x0, y0, x1, y1 = s.truth.extent()
    fig, ax = plt.subplots(figsize=(6, 8))
    ax.imshow(_map_rgb(s.updated), extent=(x0, x1, y0, y1), interpolation="nearest")
    ax.plot(tr["true"][:, 0], tr["true"][:, 1], "k-", lw=1.5, label="true")
    ax.plot(tr["previous_map"][:, 0], tr["previous_map"][:, 1], "b--", lw=1,
            label="estimated on M(i-1)")
    ax.plot(tr["initial_map"][:, 0], tr["initial_map"][:, 1], "r:", lw=1,
            label="estimated on M1")
    ax.legend(loc="lower right", fontsize=8)
    ax.set_title(f"Trajectories in {s.name}")
    _save_fig(fig, trajectories_png)
    plt.close(fig)
    # A closed figure lives on in reference cycles until the collector runs: without this a
    # run's memory climbs by the figures of several sessions.
    gc.collect()


def write_session_outputs(out_dir: Path, s) -> None:
    """What a finished update session leaves besides its maps: its TUM trajectories and its
    two figures. Written as soon as the session ends, so the run need not keep it."""
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    write_session_trajectories(out_dir, s)
    write_session_figures(out_dir, s)


def write_summary_figure(out_dir: Path, metrics: dict) -> None:
    """fig_metrics.png: CC, MS and OPDF of M(i-1), M(i) and the oracle, session by session."""
    sessions = [m for m in metrics["sessions"] if "change_detection" in m]
    if not sessions:
        return
    plt = _pyplot()
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.5))
    names = [m["name"] for m in sessions]
    x = np.arange(len(names))
    for ax, key in zip(axes, ("cc", "ms", "opdf")):
        for k, (which, label) in enumerate((("previous_vs_truth", "M(i-1)"),
                                            ("updated_vs_truth", "M(i)"),
                                            ("oracle_vs_truth", "oracle"))):
            ax.bar(x + (k - 1) * 0.27, [m["map_metrics"][which][key] for m in sessions],
                   0.27, label=label)
        ax.set_xticks(x, names)
        ax.set_title(key.upper() + " %")
    axes[0].legend(fontsize=8)
    _save_fig(fig, Path(out_dir) / "fig_metrics.png")
    plt.close(fig)


def write_sessions_figure(out_dir: Path, metrics: dict) -> None:
    """fig_sessions.png: precision, recall, OPDF and ghost cells as lines over the sessions."""
    sessions = update_sessions(metrics)
    if not sessions:
        return
    plt = _pyplot()
    fig = draw_sessions_figure(plt, sessions)
    _save_fig(fig, Path(out_dir) / "fig_sessions.png")
    plt.close(fig)


def json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"cannot write {type(o).__name__} to JSON")


def write_outputs(run) -> None:
    """What covers the whole run: metrics.json, report.md, fig_metrics.png (up to 12 update
    sessions) and fig_sessions.png (``report_sessions.run_figures``). Each session's
    maps, trajectories and figures were written when it ended (``write_session_maps``,
    ``write_session_outputs``) and are not written again: ``run.sessions`` no longer holds
    what they are drawn from."""
    out_dir = Path(run.out_dir)
    write_atomically(out_dir / "metrics.json",
                      json.dumps(run.metrics, indent=2, default=json_default) + "\n")
    write_atomically(out_dir / "report.md", render_report(run.metrics))
    writers = {"fig_metrics.png": write_summary_figure, "fig_sessions.png": write_sessions_figure}
    for name in run_figures(run.metrics):
        writers[name](out_dir, run.metrics)
