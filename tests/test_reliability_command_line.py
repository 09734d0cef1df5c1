"""Hostile input, round four: the command line's last few. A start pose off the map's free
floor, absurd numbers in a log, a gzip log cut short or holding gigabytes of comment lines, a
study whose run folder leads out of it, a damaged updater state, YAML bombs. Each case gives
its exact input and checks the exact line, the exit code, and that nothing was written (or,
where the input is usable, what was read of it)."""

from __future__ import annotations

import gzip
import json
import os
import time
import zlib
from pathlib import Path

import numpy as np
import pytest

from gridmap import OCCUPIED, UNKNOWN, OccupancyGrid, Pose2D, Scan, load_map, save_map
from gridmap.mapping import LogOddsMapper
from mapupdate import main

import ros2_tools
import synthetic_room as world
from test_reliability_files import BOX, flaser_lines
from test_reliability_hostile import BILLION_LAUGHS, refused, time_limit

START = Pose2D(8.5, 5.5, 1.5707963267948966)        # where the robot of the room's log starts


@pytest.fixture(scope="module")
def room(tmp_path_factory):
    """The room's map with the box, and a log of the robot circling it (100 FLASER lines)."""
    d = tmp_path_factory.mktemp("room")
    save_map(world.rasterise(world.room_walls() + [BOX]), d / "map.yaml")
    poses = [true for true, _, _ in world.Drive(seconds=10, rate=10.0).steps()]
    assert poses[0] == START
    (d / "run.log").write_text("\n".join(flaser_lines(poses, [0.1 * k for k in range(100)]))
                               + "\n")
    return d


def copy_room(room: Path, folder: Path) -> Path:
    """The room's map and log in a folder of the test's own, whose files the checks watch."""
    folder.mkdir()
    for f in room.iterdir():
        (folder / f.name).write_bytes(f.read_bytes())
    return folder


def ran(args, capsys) -> list[str]:
    """``mapupdate ARGS`` exits 0; its stdout lines."""
    capsys.readouterr()
    with time_limit(120):
        code = main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert code == 0, err
    return out.splitlines()


# --- 1. a start pose off the map's free floor ---------------------------------------------------
@pytest.mark.parametrize("pose, cell, message", [
    ((50.0, 50.0, 0.0), None, "the initial pose (50, 50, 0) is off the map, which spans x 0 to "
                              "11 m and y 0 to 11 m; give a pose on the map's free floor"),
    ((-0.01, 5.0, 0.0), None, "the initial pose (-0.01, 5, 0) is off the map, which spans x 0 "
                              "to 11 m and y 0 to 11 m; give a pose on the map's free floor"),
    ((5.5, 5.5, 0.0), (110, 110, OCCUPIED),        # in the box the map holds
     "the initial pose (5.5, 5.5, 0) is in an occupied cell of the map (row 110, column 110); "
     "give a pose on the map's free floor"),
    ((0.1, 0.12, 1.0), (2, 2, UNKNOWN),            # outside the room's walls
     "the initial pose (0.1, 0.12, 1) is in an unknown cell of the map (row 2, column 2); give "
     "a pose on the map's free floor"),
])
def test_a_start_pose_off_the_free_floor_is_refused_before_the_log_is_read(
        room, tmp_path, capsys, monkeypatch, pose, cell, message):
    import onboard.replay

    d = copy_room(room, tmp_path / "f")
    if cell is not None:
        row, col, value = cell
        assert load_map(d / "map.yaml").data[row, col] == value
    read = []
    monkeypatch.setattr(onboard.replay, "log_observations", lambda *a, **k: read.append(a))
    err = refused(["update", "--map", d / "map.yaml", "--log", d / "run.log", "--out",
                   d / "o.yaml", "--initial-pose", *pose, "--no-progress"], inputs=d,
                  capsys=capsys, outputs=[d / "o.yaml", d / "o.pgm"])
    assert err == f"mapupdate update: error: {message}" and read == []


def test_the_robot_s_own_start_pose_is_taken(room, tmp_path, capsys):
    d = copy_room(room, tmp_path / "f")
    lines = ran(["update", "--map", d / "map.yaml", "--log", d / "run.log", "--out",
                 d / "o.yaml", "--initial-pose", START.x, START.y, START.theta,
                 "--no-progress"], capsys)
    assert "  localiser: started at the given pose" in lines and (d / "o.yaml").exists()


# --- 2. absurd numbers in a log -------------------------------------------------------------------
def robotlaser_lines(max_range: str, reading: str, beams: int = 181) -> list[str]:
    """ROBOTLASER1 lines of the room's log (180 deg, the laser at the robot), beam 5 of each
    line replaced by ``reading``, the laser's range limit ``max_range``."""
    lines = []
    for line in flaser_lines([p for p, _, _ in world.Drive(seconds=2, rate=10.0).steps()],
                             [0.1 * k for k in range(20)], beams=beams):
        w = line.split()
        ranges = w[2:2 + beams]
        ranges[5] = reading
        pose, t = w[2 + beams:5 + beams], w[8 + beams]
        lines.append(f"ROBOTLASER1 0 -1.5707963 3.1415927 {np.pi / (beams - 1):.9f} {max_range} "
                     f"0.01 0 {beams} {' '.join(ranges)} 0 {' '.join(pose)} {' '.join(pose)} "
                     f"0 0 0 0 0 {t} h {t}")
    return lines


@pytest.mark.parametrize("kind, absurd, sane", [
    # the reading is "no return" in both: past the laser's limit, 1e300 m or 80 m
    ("ROBOTLASER1", robotlaser_lines("1e300", "1e300"), robotlaser_lines("80", "80")),
    # a reading of 1e300 m from a SICK LMS is past its "no return" 81.83 m
    ("FLASER", [" ".join(w[:7] + ["1e300"] + w[8:]) for w in
                (line.split() for line in flaser_lines([START], [0.0]))],
     [" ".join(w[:7] + ["81.83"] + w[8:]) for w in
      (line.split() for line in flaser_lines([START], [0.0]))]),
])
def test_a_range_of_1e300_maps_as_no_return(tmp_path, capsys, kind, absurd, sane):
    (tmp_path / "absurd.log").write_text("\n".join(absurd) + "\n")
    (tmp_path / "sane.log").write_text("\n".join(sane) + "\n")
    for name in ("absurd", "sane"):
        ran(["map", "--log", tmp_path / f"{name}.log", "--out", tmp_path / f"{name}.yaml",
             "--no-progress"], capsys)
    a, b = load_map(tmp_path / "absurd.yaml"), load_map(tmp_path / "sane.yaml")
    assert a.same_frame(b) and np.array_equal(a.data, b.data), kind
    assert (a.data == OCCUPIED).sum() > 100


def test_a_pose_of_1_7e308_is_a_map_too_large_not_an_overflow(tmp_path, capsys):
    lines = flaser_lines([START, START], [0.0, 0.1])
    w = lines[1].split()
    lines[1] = " ".join(w[:183] + ["1.7e308"] + w[184:])      # the laser's x
    (tmp_path / "far.log").write_text("\n".join(lines) + "\n")
    err = refused(["map", "--log", tmp_path / "far.log", "--out", tmp_path / "far.yaml",
                   "--no-progress"], inputs=tmp_path, capsys=capsys,
                  outputs=[tmp_path / "far.yaml", tmp_path / "far.pgm"])
    assert err.startswith(f"mapupdate map: error: {tmp_path / 'far.log'}: the scans span "
                          "1.7e+308 m x ") and " m, inf x " in err
    assert err.endswith(" cells at 0.05 m: more than 64000000 cells; give a coarser --resolution")


@pytest.mark.parametrize("range_max", [np.inf, 1e300])
def test_a_scan_whose_range_max_is_absurd_maps_as_one_of_50_m(range_max):
    frame = OccupancyGrid.empty(220, 220, 0.05)
    scan = world.partial_scan(world.room_walls(), START, 0.0, fov_deg=180.0, beams=181)
    ranges = np.where(np.arange(181) % 7 == 0, np.inf, scan.ranges)   # some beams see nothing
    maps = []
    for limit in (range_max, 50.0):
        mapper = LogOddsMapper(frame)
        mapper.add_scan(Scan(ranges, scan.angle_min, scan.angle_increment, 0.01, limit), START)
        maps.append(mapper.logodds)
    assert np.array_equal(*maps) and np.count_nonzero(maps[0]) > 1000


# --- 3. a gzip log cut short -------------------------------------------------------------------
@pytest.fixture()
def cut_log(room, tmp_path):
    """The room's log gzipped and cut in half; (folder, the cut file, complete lines before the
    cut, their bytes, the bytes of the line the cut went through), the last three found by
    inflating the cut file here."""
    d = copy_room(room, tmp_path / "f")
    packed = gzip.compress((d / "run.log").read_bytes(), mtime=0)
    cut = d / "run.clf.gz"
    cut.write_bytes(packed[:len(packed) // 2])
    text = zlib.decompressobj(31).decompress(cut.read_bytes())
    kept = text.rfind(b"\n") + 1
    return d, cut, text.count(b"\n"), kept, len(text) - kept


def test_a_gzip_log_cut_in_half_is_read_up_to_the_cut(cut_log, capsys):
    d, cut, complete, kept, dropped = cut_log
    assert 30 < complete < 70 and dropped > 0
    lines = ran(["update", "--map", d / "map.yaml", "--log", cut, "--out", d / "o.yaml",
                 "--no-progress"], capsys)
    warning = (f"  warning: {cut} is cut short: its gzip stream ends without its end marker "
               f"after {complete} complete lines ({kept} bytes of text); read up to the cut: "
               f"the {dropped} bytes of the line it cut through are dropped, and whatever "
               "followed it is lost")
    assert [line for line in lines if "cut short" in line] == [warning]
    assert lines[1].startswith(f"  {complete} scans read, {complete} used;")
    # the same map as the complete lines give, written as a plain log
    whole = (d / "run.log").read_text().splitlines(keepends=True)
    (d / "part.log").write_text("".join(whole[:complete]))
    ran(["update", "--map", d / "map.yaml", "--log", d / "part.log", "--out", d / "p.yaml",
         "--no-progress"], capsys)
    assert np.array_equal(load_map(d / "o.yaml").data, load_map(d / "p.yaml").data)
    lines = ran(["map", "--log", cut, "--out", d / "m.yaml", "--no-progress"], capsys)
    assert lines[1] == f"  {complete} of {complete} scans mapped (poses: recorded)"
    assert lines[2] == warning


@pytest.mark.parametrize("flag", ["--refuse-truncated", "--strict"])
def test_a_cut_gzip_log_is_refused_on_request(cut_log, capsys, flag):
    d, cut, complete, kept, _ = cut_log
    for command in (["update", "--map", d / "map.yaml"], ["map"]):
        err = refused([*command, "--log", cut, "--out", d / "o.yaml", flag, "--no-progress"],
                      inputs=d, capsys=capsys, outputs=[d / "o.yaml", d / "o.pgm"])
        assert err == (f"mapupdate {command[0]}: error: {cut} is cut short: its gzip stream "
                       f"ends without its end marker after {complete} complete lines ({kept} "
                       "bytes of text); refused (--refuse-truncated or --strict; without them "
                       "a cut log is read up to the cut)")


def test_a_gzip_log_damaged_inside_is_still_refused(room, tmp_path, capsys):
    d = copy_room(room, tmp_path / "f")
    packed = bytearray(gzip.compress((d / "run.log").read_bytes(), mtime=0))
    packed[len(packed) // 2] ^= 0xFF
    (d / "bad.clf.gz").write_bytes(bytes(packed))
    err = refused(["update", "--map", d / "map.yaml", "--log", d / "bad.clf.gz", "--out",
                   d / "o.yaml", "--no-progress"], inputs=d, capsys=capsys,
                  outputs=[d / "o.yaml"])
    assert err.startswith(f"mapupdate update: error: {d / 'bad.clf.gz'}: cannot read: ")


# --- 4. gigabytes of comment lines in a small gzip file --------------------------------------
def test_a_gzip_log_of_270_million_comment_lines_is_refused_within_seconds(room, tmp_path,
                                                                           capsys):
    d = copy_room(room, tmp_path / "f")
    member = gzip.compress(b"# comment\n" * 10_000, mtime=0)    # 100 KB in 243 bytes
    bomb = d / "comments.clf.gz"
    bomb.write_bytes(member * 27_000)            # 6.6 MB: 270 million lines, 2.7 GB of text
    size = bomb.stat().st_size
    t0 = time.perf_counter()
    err = refused(["update", "--map", d / "map.yaml", "--log", bomb, "--out", d / "o.yaml",
                   "--no-progress"], inputs=d, capsys=capsys, outputs=[d / "o.yaml"])
    # a line per 4 bytes of the file: 1.6 million lines counted (0.03 s), not 270 million parsed
    assert time.perf_counter() - t0 < 2
    assert err == (f"mapupdate update: error: {bomb}: the gzip file holds more than {size // 4} "
                   "lines, over a line per 4 bytes of it where a log's line takes 14 or more "
                   "(a gzip bomb of short lines?); refused (--max-log-lines N raises the bound)")


def test_the_bounds_on_a_log_are_set_on_the_command_line(room, tmp_path, capsys):
    d = copy_room(room, tmp_path / "f")
    log, size = d / "run.log", (d / "run.log").stat().st_size
    (d / "run.clf.gz").write_bytes(gzip.compress(log.read_bytes(), mtime=0))
    for path, option, bound, what in ((log, "--max-log-lines", 99, "99 lines"),
                                      (log, "--max-log-bytes", size - 1,
                                       f"{size - 1} bytes of text"),
                                      (d / "run.clf.gz", "--max-log-lines", 50, "50 lines")):
        err = refused(["update", "--map", d / "map.yaml", "--log", path, "--out", d / "o.yaml",
                       option, bound, "--no-progress"], inputs=d, capsys=capsys,
                      outputs=[d / "o.yaml"])
        assert err == (f"mapupdate update: error: {path}: holds more than {what}, the bound "
                       f"{option} gives; refused")
    lines = ran(["update", "--map", d / "map.yaml", "--log", log, "--out", d / "o.yaml",
                 "--max-log-lines", 100, "--max-log-bytes", size, "--no-progress"], capsys)
    assert lines[1].startswith("  100 scans read, 100 used;")
    for bad in ("0", "-5", "1e9"):
        with pytest.raises(SystemExit) as stop:
            main(["map", "--log", str(log), "--out", str(d / "o.yaml"), "--max-log-lines", bad])
        assert stop.value.code == 2
        assert capsys.readouterr().err.strip() == (
            f"mapupdate map: error: argument --max-log-lines: must be a whole number >= 1, got "
            f"{bad!r} (see mapupdate map --help)")


DATA = Path(__file__).resolve().parents[2] / "shared/data"


def test_the_default_bounds_leave_the_real_logs_three_times_the_room_they_need():
    from robotlogs.carmen import read_carmen
    from robotlogs.text_lines import GZIP_BYTES_PER_LINE, GZIP_MAX_RATIO

    logs = sorted(DATA.glob("*.gz")) + sorted(DATA.glob("radish/*.gz"))
    if not logs:
        pytest.skip(f"no gzip logs in {DATA}")
    for path in logs:
        text = gzip.decompress(path.read_bytes())
        size = path.stat().st_size
        assert 3 * text.count(b"\n") * GZIP_BYTES_PER_LINE <= size, path.name
        assert 3 * len(text) <= GZIP_MAX_RATIO * size, path.name
        assert read_carmen(path, strict=True).records, path.name


# --- 5. a study whose run folder leads out of it ---------------------------------------------
def test_summarise_refuses_a_run_folder_that_a_link_leads_out_of_the_study(tmp_path, capsys):
    study, outside = tmp_path / "study", tmp_path / "outside"
    (study / "runs").mkdir(parents=True)
    outside.mkdir()
    (outside / "result.json").write_text(json.dumps(
        {"run": {}, "rows": [{"scenario": "stolen", "seed": 1, "method": "none",
                              "session": "W2"}]}))
    os.symlink("../../outside", study / "runs" / "a")          # climbs out with ..
    (study / "sweep.json").write_text(json.dumps({"format": 1, "spec": {}, "runs": ["a"]}))
    err = refused(["sweep", "--summarise", study], inputs=tmp_path, capsys=capsys,
                  outputs=[study / "results.csv", study / "summary.md"])
    assert err == (f"mapupdate sweep: error: {study / 'runs' / 'a'}: the run's folder leads out "
                   f"of the study, to {outside.resolve()}; a study's runs are folders of its own")
    assert sorted(p.name for p in study.iterdir()) == ["runs", "sweep.json"]


# --- 6. a damaged updater state ----------------------------------------------------------------
@pytest.fixture(scope="module")
def state(room, tmp_path_factory):
    """A state of the robot's profile (N_b 10, the flag counts in the bits above the flags)."""
    d = tmp_path_factory.mktemp("state")
    assert main(["update", "--map", room / "map.yaml", "--log", room / "run.log", "--out",
                 d / "o.yaml", "--state", d / "s.npz", "--no-progress"]) == 0
    with np.load(d / "s.npz") as z:
        arrays = dict(z)
    meta = json.loads(str(arrays["meta"]))
    assert meta["config"]["buffer_size"] == 10 and meta["config"]["unanimous_min"] > 0
    return arrays


def write_state(arrays: dict, path: Path, **meta_edits) -> Path:
    meta = json.loads(str(arrays["meta"]))
    meta.update(meta_edits)
    meta = {k: v for k, v in meta.items() if v is not None}
    with open(path, "wb") as f:
        np.savez(f, **{**arrays, "meta": np.array(json.dumps(meta))})
    return path


def update_with(room, state: Path, out: Path) -> list:
    return ["update", "--map", room / "map.yaml", "--log", room / "run.log", "--out", out,
            "--state", state, "--no-progress"]


def test_the_updater_s_own_buffers_hold_no_flag_beyond_their_count(state):
    counts, flags = state["hist"] >> 10, state["hist"] & 0x3FF
    assert np.count_nonzero(flags >> np.minimum(counts, 10)) == 0
    # flags kept, and counts on both sides of N_b = 10
    assert np.count_nonzero(flags) > 50 and counts.min() < 10 < counts.max()


def test_a_state_with_bits_set_beyond_n_b_is_refused_as_damaged(room, state, tmp_path, capsys):
    hist = state["hist"] | np.uint16(1 << 15)        # every cell's top bit, beyond N_b = 10
    bad = write_state({**state, "hist": hist}, tmp_path / "bad.npz")
    saved = json.loads(str(state["meta"]))["checksums"]["hist"]
    err = refused(update_with(room, bad, tmp_path / "o.yaml"), inputs=tmp_path, capsys=capsys,
                  outputs=[tmp_path / "o.yaml"])
    assert err == (f"mapupdate update: error: {bad}: a damaged state: its buffers are not as "
                   f"saved (CRC-32 {zlib.crc32(hist.tobytes()):#010x}, saved {saved:#010x})")


def test_a_state_saved_before_the_checksums_is_checked_flag_by_count(room, state, tmp_path,
                                                                     capsys):
    old = write_state(state, tmp_path / "old.npz", checksums=None)
    ran(update_with(room, old, tmp_path / "whole.yaml"), capsys)        # whole, it loads
    hist = state["hist"].copy()
    first = int(np.flatnonzero((hist >> 10) == 1)[0])          # a cell flagged once
    hist.flat[first] |= np.uint16(1 << 5)                      # a flag five scans back
    bad = write_state({**state, "hist": hist}, tmp_path / "bad.npz", checksums=None)
    row, col = divmod(first, hist.shape[1])
    err = refused(update_with(room, bad, tmp_path / "o.yaml"), inputs=tmp_path, capsys=capsys,
                  outputs=[tmp_path / "o.yaml"])
    assert err == (f"mapupdate update: error: {bad}: a damaged state: 1 cells' buffers hold "
                   "flags further back than the cell's flag count, which no scan pushed (the "
                   f"first at row {row}, column {col}: count 1, flags "
                   f"{int(hist.flat[first]) & 0x3FF:#b})")


# --- 7. YAML bombs -----------------------------------------------------------------------------
def test_yaml_bombs_are_refused_in_one_line_by_every_command(room, tmp_path, capsys):
    d = copy_room(room, tmp_path / "f")
    bomb = d / "laughs.yaml"
    bomb.write_text(BILLION_LAUGHS)
    (d / "spec.yaml").write_text(f"scenarios: [{bomb}]\nseeds: [1]\nmethods: [none]\n")
    line = f"{bomb}: the YAML expands to more than 1000000 nodes through its aliases (refused)"
    out = d / "out"
    for args, prefix in (
            (["compare", bomb, d / "map.yaml"], ""),
            (["update", "--map", bomb, "--log", d / "run.log", "--out", out / "o.yaml"], ""),
            (["update", "--map", d / "map.yaml", "--log", d / "run.log", "--out", out / "o.yaml",
              "--config", bomb], ""),
            (["inject", "--map", bomb, "--log", d / "run.log", "--out", out, "--seed", 1], ""),
            (["run", bomb, "--quick", "--out", out], ""),
            (["render", bomb, "--out", d / "w.png"], ""),
            (["fleet", "--scenario", bomb, "--quick", "--out", out], ""),
            (["sweep", bomb, "--out", out], ""),
            (["sweep", d / "spec.yaml", "--out", out], f"{d / 'spec.yaml'}: scenarios[0]: ")):
        err = refused(args + (["--no-progress"] if args[0] not in ("compare", "render") else []),
                      inputs=d, capsys=capsys, outputs=[out, d / "w.png"])
        assert err == f"mapupdate {args[0]}: error: {prefix}{line}", args


@pytest.mark.skipif(bool(ros2_tools.missing()), reason=ros2_tools.missing() or "")
def test_the_ros2_node_started_on_a_yaml_bomb_says_so_in_one_line(room, tmp_path):
    (tmp_path / "laughs.yaml").write_text(BILLION_LAUGHS)
    graph = ros2_tools.Graph(tmp_path)
    try:
        for name, args in (("map_bomb", ["--map", tmp_path / "laughs.yaml"]),
                           ("config_bomb", ["--map", room / "map.yaml", "--config",
                                            tmp_path / "laughs.yaml"])):
            node = graph.node(*args, "--autostart", name=name)
            assert node.wait(90) == 2
            assert graph.log(name).splitlines() == [
                f"mapupdate ros2: error: the node did not come up: configure failed: "
                f"{tmp_path / 'laughs.yaml'}: the YAML expands to more than 1000000 nodes "
                "through its aliases (refused)"]
    finally:
        graph.close()
