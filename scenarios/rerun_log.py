"""Recordings of a run for the rerun viewer, scan by scan. The only module that imports rerun.

``RerunRecorder`` is a ``runner.SessionObserver``: ``mapupdate run --rerun run.rrd`` hands one to
the runner, which tells it of every update session's start, scans and end. Open the file with
``rerun run.rrd``.

Timelines: ``sim_time`` (simulated seconds, sessions one after the other) and ``scan`` (scan
index over the whole run). Everything spatial is in the map frame, metres, z up; the maps lie
flat at z = 0 with the overlays just above them. What is logged "every scan" gets one row per
scan, sent as columns once per map period (far cheaper than a call per scan).

=============================  ==============  ================================================
entity                         archetype       logged
=============================  ==============  ================================================
world/truth/objects            LineStrips3D    session start: walls and objects of the world
world/truth/G                  GridMap         session start: ground truth G_i
world/maps/reference           GridMap         session start: M_{i-1}
world/maps/updated             GridMap         when changed, at most once per ``map_period``
world/maps/changed             Points3D        with it: cells of M_i that differ from M_{i-1}
world/maps/change_counts       GridMap         when changed, at most once per ``map_period``
world/robot/true               Arrows3D        every scan
world/robot/estimate           Arrows3D        every scan
world/robot/true_path          LineStrips3D    every PATH_PERIOD, and at session end
world/robot/estimated_path     LineStrips3D    every PATH_PERIOD, and at session end
world/particles                Points3D        after every update of the localiser's filter
world/scan                     Points3D        every scan, at the estimated sensor pose,
                                               coloured by verdict (topview.VERDICT_COLORS)
world/people                   Points3D        every scan
scores/localization_error      Scalars         every scan [m]
scores/cells_changed           Scalars         every scan (the decision rule's count)
scores/correct_changes         Scalars         with the maps
scores/wrong_changes           Scalars         with the maps
scores/session/<metric>        Scalars         session end: f1, precision, recall, cc, ...
log/sessions                   TextLog         session start and end
=============================  ==============  ================================================
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

import evaluation as ev
from gridmap import FREE, OCCUPIED, OccupancyGrid, Pose2D
from sim import geometry as geo

from .topview import CELL_COLORS, UNCLASSIFIED, VERDICT_COLORS, scan_points

MAP_PERIOD = 1.0          # [s] of simulated time between two logs of the maps at most
PATH_PERIOD = 5.0         # [s] between two logs of the trajectories (each log holds all of it)
SESSION_GAP = 1.0         # [s] on the sim_time timeline between two sessions
Z_MAP, Z_OVERLAY = 0.0, 0.05
ENTITIES = ("world/truth/objects", "world/truth/G", "world/maps/reference",
            "world/maps/updated", "world/maps/changed", "world/maps/change_counts",
            "world/robot/true", "world/robot/estimate", "world/robot/true_path",
            "world/robot/estimated_path", "world/particles", "world/scan", "world/people",
            "scores/localization_error", "scores/cells_changed", "scores/correct_changes",
            "scores/wrong_changes", "log/sessions")
VERDICT_NAMES = ("invalid", "unchanged", "skipped", "detected change")   # updater.BEAM_* order
UNCLASSIFIED_CLASS = len(VERDICT_NAMES)


def has_display() -> bool:
    """Whether a viewer window could open here."""
    return sys.platform in ("darwin", "win32") or bool(os.environ.get("DISPLAY")
                                                       or os.environ.get("WAYLAND_DISPLAY"))


def grid_map(grid: OccupancyGrid, z: float = Z_MAP) -> rr.GridMap:
    """An occupancy grid as rerun's GridMap with RViz's map colours. Rerun puts the first image
    row at the top (largest y), the grid's first row is its southern edge: rows are flipped."""
    data = np.ascontiguousarray(grid.data[::-1]).view(np.uint8)
    return rr.GridMap(data=data.tobytes(),
                      format=rr.components.ImageFormat(width=grid.width, height=grid.height,
                                                       color_model="L", channel_datatype="U8"),
                      cell_size=grid.resolution, translation=[*grid.origin, z],
                      colormap=rr.components.Colormap.RvizMap)


def heat_map(counts: np.ndarray, frame: OccupancyGrid, z: float = Z_MAP + 0.01) -> rr.GridMap:
    """Change counts n_c (H, W) as a transparent-where-zero yellow-to-red RGBA GridMap."""
    top = max(int(counts.max()), 1)
    f = counts[::-1].astype(np.float32) / top
    rgba = np.zeros(counts.shape + (4,), np.uint8)
    rgba[..., 0] = 255
    rgba[..., 1] = (220 * (1.0 - f)).astype(np.uint8)
    rgba[..., 3] = np.where(counts[::-1] > 0, 90 + (165 * f).astype(np.uint8), 0)
    return rr.GridMap(data=rgba.tobytes(),
                      format=rr.components.ImageFormat(width=frame.width, height=frame.height,
                                                       color_model="RGBA",
                                                       channel_datatype="U8"),
                      cell_size=frame.resolution, translation=[*frame.origin, z])


def _xyz(xy: np.ndarray, z: float) -> np.ndarray:
    xy = np.asarray(xy, np.float32).reshape(-1, 2)
    return np.column_stack([xy, np.full(len(xy), z, np.float32)])


def outlines(world) -> rr.LineStrips3D:
    """Walls and objects of a ``sim.World`` as closed outlines."""
    strips = [np.vstack([c, c[:1]]) for c in geo.box_corners(world.boxes)]
    a = np.linspace(0.0, 2 * math.pi, 25)
    strips += [np.column_stack([x + r * np.cos(a), y + r * np.sin(a)])
               for x, y, r in world.circles]
    return rr.LineStrips3D([_xyz(s, Z_OVERLAY) for s in strips], colors=[[120, 120, 120]],
                           radii=0.02)


def blueprint(bounds) -> rrb.Blueprint:
    """The layout: the live map large on the left; the truth and the buffers in tabs, and the
    scores, on the right. Both map views look straight down at the warehouse."""
    x0, y0, x1, y1 = bounds
    cx, cy, h = (x0 + x1) / 2, (y0 + y1) / 2, 1.6 * max(x1 - x0, y1 - y0)
    # a small tilt keeps the orbit's up axis (z) off the line of sight; north stays up
    eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=(cx, cy - 0.02 * h, h),
                            look_target=(cx, cy, 0.0), eye_up=(0.0, 0.0, 1.0))

    def view(name, contents):
        return rrb.Spatial3DView(name=name, origin="/", contents=contents, eye_controls=eye,
                                 line_grid=False)

    live = view("updated map, scan, poses", [
        "+ /world/maps/updated", "+ /world/maps/changed", "+ /world/scan", "+ /world/robot/**",
        "+ /world/particles", "+ /world/people", "+ /world/truth/objects"])
    truth = view("ground truth G", ["+ /world/truth/**", "+ /world/people",
                                    "+ /world/robot/true", "+ /world/robot/true_path"])
    buffers = view("reference map and change counts", [
        "+ /world/maps/reference", "+ /world/maps/change_counts", "+ /world/robot/estimate"])
    return rrb.Blueprint(
        rrb.Horizontal(
            live,
            rrb.Vertical(rrb.Tabs(truth, buffers),
                         rrb.TimeSeriesView(name="scores", origin="/scores"),
                         rrb.TextLogView(name="sessions", origin="/log"),
                         row_shares=[3, 2, 1]),
            column_shares=[3, 2]),
        collapse_panels=True)


class RerunRecorder:
    """Writes a run to ``path`` (.rrd) and/or streams it to a viewer it spawns (``spawn``)."""

    def __init__(self, path: str | Path | None = None, spawn: bool = False,
                 map_period: float = MAP_PERIOD, application_id: str = "mapupdate"):
        if path is None and not spawn:
            raise ValueError("RerunRecorder needs a file to write or a viewer to spawn")
        self.rec = rr.RecordingStream(application_id)
        sinks = []
        if spawn:
            self.rec.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        if path is not None:
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(path)))
        self.rec.set_sinks(*sinks)
        self.path = path
        self.map_period = float(map_period)
        self._offset = 0.0        # sim_time of the current session's t = 0
        self._scan = 0
        self._rows = self._empty_rows()
        self._blueprint_sent = False

    # --- the observer calls ---------------------------------------------------------------------
    def session_start(self, scenario, session: int, world, previous: OccupancyGrid,
                      initial: OccupancyGrid, updater, localizer) -> None:
        rec = self.rec
        if not self._blueprint_sent:
            self._log_styles()
            rec.send_blueprint(blueprint(scenario.world.bounds))
            self._blueprint_sent = True
        self._name = scenario.sessions[session].name
        self._mounts = [lidar.mount for lidar in scenario.robot.lidars]
        self._length = 1.5 * scenario.robot.radius
        self._previous = previous
        self._truth = world.ground_truth()
        self._truth_free = self._truth.data == FREE
        self._near_truth_occupied = ev.near(self._truth.data == OCCUPIED)
        self._next_map_time = self._next_path_time = 0.0
        self._map_key = self._counts = None
        self._estimate_obj = None
        self._true_path, self._est_path = [], []
        self._t = 0.0
        self._set_time(0.0)
        rec.log("log/sessions", rr.TextLog(f"{self._name} starts: {len(world.obstacles)} "
                                           f"objects, {len(world.people())} people"))
        rec.log("world/truth/objects", outlines(world))
        rec.log("world/truth/G", grid_map(self._truth, Z_MAP - 0.02))
        rec.log("world/maps/reference", grid_map(previous, Z_MAP - 0.01))

    def scan(self, msg, estimate: Pose2D, report, world, updater, localizer) -> None:
        # Kept as arrays and sent a map period at a time as columns: one call per entity per
        # second instead of several per scan is what keeps the recording cheap.
        b = self._rows
        sensor = estimate.compose(self._mounts[msg.lidar])
        pts = scan_points(msg.scan.ranges, msg.scan.angles(), sensor)
        ok = np.isfinite(pts[:, 0])
        classes = np.full(int(ok.sum()), UNCLASSIFIED_CLASS, np.uint16) \
            if report.verdicts is None else np.asarray(report.verdicts, np.uint16)[ok]
        b["scan"].append(self._scan)
        b["time"].append(self._offset + msg.time)
        b["points"].append(pts[ok])
        b["classes"].append(classes)
        b["people"].append(world.people())
        b["true"].append(msg.true_pose.as_array())
        b["estimate"].append(estimate.as_array())
        b["error"].append(math.hypot(estimate.x - msg.true_pose.x, estimate.y - msg.true_pose.y))
        b["changed"].append(float(updater.n_changed))
        est_obj = localizer.estimate()
        if est_obj is not self._estimate_obj:     # a new estimate: the filter has updated
            self._estimate_obj = est_obj
            b["particle_rows"].append(len(b["scan"]) - 1)
            b["particles"].append(localizer.particles[:, :2])
        self._true_path.append((msg.true_pose.x, msg.true_pose.y))
        self._est_path.append((estimate.x, estimate.y))
        self._t = msg.time
        if msg.time >= self._next_map_time:
            self._flush_rows()
            self._set_time(msg.time)
            self._log_maps(updater, msg.time)
        self._scan += 1

    def session_end(self, result) -> None:
        self._flush_rows()
        self._set_time(self._t, max(self._scan - 1, 0))
        m = result.metrics
        cd, upd = m["change_detection"], m["map_metrics"]["updated_vs_truth"]
        values = {"f1": cd["f1"], "precision": cd["precision"], "recall": cd["recall"],
                  "cc": upd["cc"], "ms": upd["ms"], "opdf": upd["opdf"],
                  "ghost_cells": m["ghost_cells"],
                  "ape_rmse": m["localization"]["previous_map"]["rmse"]}
        for k, v in values.items():
            if v is not None:
                self.rec.log(f"scores/session/{k}", rr.Scalars(float(v)))
        self._log_paths()
        self.rec.log("log/sessions", rr.TextLog(
            f"{result.name} ends: " + ", ".join(f"{k} {v:.3f}" for k, v in values.items()
                                                 if v is not None)))
        self._offset += m["resources"]["simulated_s"] + SESSION_GAP

    def close(self) -> None:
        """Flush and close the recording (the file is complete after this)."""
        self.rec.flush()
        self.rec.disconnect()

    # --- helpers ----------------------------------------------------------------------------------
    @staticmethod
    def _empty_rows() -> dict:
        keys = ("scan", "time", "points", "classes", "people", "true", "estimate", "error",
                "changed", "particle_rows", "particles")
        return {k: [] for k in keys}

    def _flush_rows(self) -> None:
        """Send the scans kept since the last flush, one row per scan and entity."""
        b, send = self._rows, self.rec.send_columns
        if not b["scan"]:
            return
        scans, times = np.asarray(b["scan"]), np.asarray(b["time"])

        def index(rows=slice(None)):
            return [rr.TimeColumn("scan", sequence=scans[rows]),
                    rr.TimeColumn("sim_time", duration=times[rows])]

        send("world/scan", indexes=index(), columns=rr.Points3D.columns(
            positions=_xyz(np.concatenate(b["points"]), Z_OVERLAY),
            class_ids=np.concatenate(b["classes"])).partition([len(p) for p in b["points"]]))
        people = np.concatenate(b["people"])
        send("world/people", indexes=index(), columns=rr.Points3D.columns(
            positions=_xyz(people[:, :2], Z_OVERLAY), radii=people[:, 2].astype(np.float32)
        ).partition([len(p) for p in b["people"]]))
        for entity, key in (("world/robot/true", "true"), ("world/robot/estimate", "estimate")):
            poses = np.asarray(b[key])
            send(entity, indexes=index(), columns=rr.Arrows3D.columns(
                origins=_xyz(poses[:, :2], Z_OVERLAY),
                vectors=np.column_stack([self._length * np.cos(poses[:, 2]),
                                         self._length * np.sin(poses[:, 2]),
                                         np.zeros(len(poses))]).astype(np.float32)))
        send("scores/localization_error", indexes=index(),
             columns=rr.Scalars.columns(scalars=np.asarray(b["error"])))
        send("scores/cells_changed", indexes=index(),
             columns=rr.Scalars.columns(scalars=np.asarray(b["changed"])))
        if b["particles"]:
            rows = np.asarray(b["particle_rows"])
            send("world/particles", indexes=index(rows), columns=rr.Points3D.columns(
                positions=_xyz(np.concatenate(b["particles"]), Z_OVERLAY)
            ).partition([len(p) for p in b["particles"]]))
        self._rows = self._empty_rows()

    def _log_styles(self) -> None:
        """What never changes: the frame, the verdicts' names and colours, point sizes."""
        rec = self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        classes = [(code, name, tuple(int(c) for c in VERDICT_COLORS[code]))
                   for code, name in enumerate(VERDICT_NAMES)]
        classes.append((UNCLASSIFIED_CLASS, "not classified (gated)", UNCLASSIFIED))
        rec.log("world/scan", rr.AnnotationContext(classes), static=True)
        rec.log("world/scan", rr.Points3D.from_fields(radii=0.03), static=True)
        rec.log("world/people", rr.Points3D.from_fields(colors=[[245, 130, 48]]), static=True)
        rec.log("world/particles", rr.Points3D.from_fields(colors=[[90, 90, 200]], radii=0.015),
                static=True)
        rec.log("world/robot/true", rr.Arrows3D.from_fields(colors=[[31, 119, 180]], radii=0.04),
                static=True)
        rec.log("world/robot/estimate", rr.Arrows3D.from_fields(colors=[[60, 180, 75]],
                                                                radii=0.04), static=True)

    def _set_time(self, t: float, scan: int | None = None) -> None:
        self.rec.set_time("sim_time", duration=self._offset + t)
        self.rec.set_time("scan", sequence=self._scan if scan is None else scan)

    def _log_maps(self, updater, t: float) -> None:
        """The updated map, its changes and the change counts, each only if it changed since
        its last log; called at most once per map period."""
        self._next_map_time = t + self.map_period
        counts = updater.change_counts()
        if self._counts is None or not np.array_equal(counts, self._counts):
            self._counts = counts
            self.rec.log("world/maps/change_counts", heat_map(counts, self._previous))
        rows, cols = updater.changed_cells()
        key = (rows.tobytes(), cols.tobytes())
        if key != self._map_key:
            self._map_key = key
            updated = updater.updated_map()
            self.rec.log("world/maps/updated", grid_map(updated))
            changed = updated.data != self._previous.data
            r, c = np.nonzero(changed)
            xy = np.column_stack(self._previous.cell_to_world(r, c))
            colors = np.where((updated.data[r, c] == FREE)[:, None],
                              np.array(CELL_COLORS["freed"], np.uint8),
                              np.array(CELL_COLORS["added"], np.uint8))
            self.rec.log("world/maps/changed", rr.Points3D(
                _xyz(xy, Z_OVERLAY - 0.02), colors=colors, radii=0.5 * updated.resolution))
            correct = changed & (((updated.data == FREE) & self._truth_free)
                                 | ((updated.data == OCCUPIED) & self._near_truth_occupied))
            n_correct = int(np.count_nonzero(correct))
            self.rec.log("scores/correct_changes", rr.Scalars(float(n_correct)))
            self.rec.log("scores/wrong_changes", rr.Scalars(float(changed.sum() - n_correct)))
        if t >= self._next_path_time:
            self._next_path_time = t + PATH_PERIOD
            self._log_paths()

    def _log_paths(self) -> None:
        if self._true_path:
            self.rec.log("world/robot/true_path", rr.LineStrips3D(
                [_xyz(self._true_path, Z_OVERLAY)], colors=[[31, 119, 180]], radii=0.02))
            self.rec.log("world/robot/estimated_path", rr.LineStrips3D(
                [_xyz(self._est_path, Z_OVERLAY)], colors=[[60, 180, 75]], radii=0.02))
