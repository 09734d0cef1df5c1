"""Hostile input and faults through the command line, as a careless user or a faulty robot
makes them. Each case is generated here, run through ``mapupdate`` in-process under a time
limit, and must end in one of two ways: a refusal (exit 2, one line naming the file, key or
value, no traceback, no partial output) or a correct result; and no input file may change."""

from __future__ import annotations

import contextlib
import copy
import hashlib
import io
import json
import os
import signal
import zlib
from pathlib import Path

import numpy as np
import pytest
import yaml
from PIL import Image

from gridmap import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, load_map, save_map
from mapupdate import main
from tiny_room import tiny_room_dict

LIMIT_S = 60       # no case may run longer: a hang is a failure, not a wait


@contextlib.contextmanager
def time_limit(seconds: int):
    def fire(*_):
        raise TimeoutError(f"still running after {seconds} s")
    old = signal.signal(signal.SIGALRM, fire)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def checksums(folder: Path) -> dict:
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file() and not p.is_symlink():
            out[str(p)] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def refused(args, *words, inputs: Path, capsys, outputs=()):
    """``mapupdate ARGS`` refuses in one line holding ``words``; nothing in ``inputs`` changed
    and none of ``outputs`` was written."""
    before = checksums(inputs)
    capsys.readouterr()
    with time_limit(LIMIT_S):
        code = main([str(a) for a in args])
    err = capsys.readouterr().err.strip()
    assert code == 2, f"exit {code}, stderr {err!r}"
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, f"{w!r} not in {err!r}"
    assert checksums(inputs) == before
    for o in outputs:
        assert not Path(o).exists(), f"{o} was written"
    leftovers = [p for p in inputs.rglob("*") if ".tmp" in p.name or ".partial" in p.name]
    assert not leftovers, leftovers
    return err


# --- maps ---------------------------------------------------------------------------------------
def write_yaml_map(folder: Path, image: str, resolution=0.05, name="m.yaml") -> Path:
    path = folder / name
    path.write_text(f"image: {image}\nresolution: {resolution!r}\norigin: [0.0, 0.0, 0.0]\n"
                    "negate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n")
    return path


def reference_grid() -> OccupancyGrid:
    cells = np.full((12, 16), FREE, np.int8)
    cells[0, :] = cells[-1, :] = cells[:, 0] = cells[:, -1] = OCCUPIED
    cells[4:7, 5:9] = UNKNOWN
    return OccupancyGrid(cells, 0.05, (0.0, 0.0))


def grey_levels(grid: OccupancyGrid) -> np.ndarray:
    """map_saver's grey levels, image row 0 on top."""
    from gridmap.map_io import trinary_image

    return trinary_image(grid)


PNG_CASES = {
    # 16-bit greyscale: the same levels scaled to 16 bits (x 257) must read the same
    "16-bit grey": lambda g: Image.fromarray(grey_levels(g).astype(np.uint16) * 257),
    # colour: walls pure green (mean 85: occ 0.67, occupied), free white, unknown grey
    "green walls": lambda g: Image.fromarray(np.stack(
        [np.where(grey_levels(g) == 0, 0, grey_levels(g)),
         np.where(grey_levels(g) == 0, 255, grey_levels(g)),
         np.where(grey_levels(g) == 0, 0, grey_levels(g))], axis=2).astype(np.uint8), "RGB"),
    "grey with alpha": lambda g: Image.fromarray(np.stack(
        [grey_levels(g), np.full(grey_levels(g).shape, 255, np.uint8)], axis=2), "LA"),
    "palette": lambda g: Image.fromarray(grey_levels(g), "L").convert("P"),
}


@pytest.mark.parametrize("kind", sorted(PNG_CASES))
def test_png_maps_read_as_map_server_reads_them(tmp_path, kind):
    grid = reference_grid()
    PNG_CASES[kind](grid).save(tmp_path / "m.png")
    got = load_map(write_yaml_map(tmp_path, "m.png"))
    assert np.array_equal(got.data, grid.data), kind


def png_bomb(path: Path) -> None:
    """A valid PNG header claiming 100000 x 100000 pixels, in 201 bytes or so."""
    raw = io.BytesIO()
    Image.new("L", (1, 1)).save(raw, "PNG")
    data = bytearray(raw.getvalue())
    data[16:24] = (100000).to_bytes(4, "big") * 2            # IHDR width, height
    crc = zlib.crc32(bytes(data[12:29])) & 0xFFFFFFFF
    data[29:33] = crc.to_bytes(4, "big")
    path.write_bytes(bytes(data))


BILLION_LAUGHS = "a: &a [lol, lol, lol, lol, lol, lol, lol, lol, lol]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [{', '.join(['*' + chr(97 + i)] * 9)}]\n" for i in range(8))


def hostile_maps(folder: Path):
    """(case, map path, the words of its refusal)."""
    png_bomb(folder / "bomb.png")
    yield "png bomb", write_yaml_map(folder, "bomb.png", name="bomb.yaml"), \
        ("bomb.png", "claims more pixels than the 64000000 cells")
    os.symlink("/dev/zero", folder / "zero.pgm")
    yield "endless image", write_yaml_map(folder, "zero.pgm", name="zeroimg.yaml"), \
        ("zero.pgm", "not a regular file")
    (folder / "laughs.yaml").write_text(BILLION_LAUGHS)
    yield "billion laughs", folder / "laughs.yaml", ("laughs.yaml", "aliases")
    os.symlink("/dev/zero", folder / "zero.yaml")
    yield "endless yaml", folder / "zero.yaml", ("zero.yaml", "not a regular file")
    (folder / "bin.yaml").write_bytes(bytes(range(256)) * 4)
    yield "binary yaml", folder / "bin.yaml", ("bin.yaml", "binary")
    save_map(reference_grid(), folder / "good.yaml")
    for res in (1e-200, 1e-160, 1e300, 0.0):
        name = f"res{res:g}.yaml"
        yield f"resolution {res:g}", write_yaml_map(folder, "good.pgm", res, name), \
            (name, "resolution must be in [0.001, 10]")


def test_hostile_maps_are_refused_in_one_line(tmp_path, capsys):
    good = tmp_path / "good.yaml"
    for case, path, words in hostile_maps(tmp_path):
        for args in (["compare", path, good],
                     ["update", "--map", path, "--log", tmp_path / "none.log", "--out",
                      tmp_path / "out" / "o.yaml", "--no-progress"]):
            refused(args, *words, inputs=tmp_path, capsys=capsys,
                    outputs=[tmp_path / "out" / "o.yaml"])


# --- update: outputs never overwrite inputs --------------------------------------------------
@pytest.fixture(scope="module")
def small_log(tmp_path_factory):
    """A map and a CARMEN log of a robot standing in it, with corrected poses."""
    folder = tmp_path_factory.mktemp("log")
    grid = reference_grid()
    save_map(grid, folder / "m.yaml")
    ranges = " ".join(["0.3"] * 180)
    lines = [f"FLASER 180 {ranges} 0.4 0.3 0.0 0.4 0.3 0.0 {t:.1f} host {t:.1f}"
             for t in range(5)]
    (folder / "run.log").write_text("\n".join(lines) + "\n")
    return folder


@pytest.mark.parametrize("out, state", [
    ("m.yml", None), ("m", None), ("m.yaml", None), ("sub/../m.yaml", None),
    ("o.yaml", "o.pgm"), ("o.yaml", "o.yaml"), ("o.yaml", "m.pgm"), ("run.log", None)])
def test_update_refuses_outputs_that_are_inputs_or_each_other(small_log, tmp_path, out, state,
                                                              capsys):
    folder = tmp_path / "f"
    folder.mkdir()
    (folder / "sub").mkdir()
    for f in small_log.iterdir():
        (folder / f.name).write_bytes(f.read_bytes())
    args = ["update", "--map", folder / "m.yaml", "--log", folder / "run.log", "--out",
            folder / out, "--no-progress"] + (["--state", folder / state] if state else [])
    refused(args, "would write", "choose another path", inputs=folder, capsys=capsys)


def test_a_state_starts_the_next_session_on_the_map_its_session_made(small_log, tmp_path,
                                                                      capsys):
    """--new-session starts the next session from a state on any map of its frame (said in
    the summary), and needs --state. (The map the state's session made, given without it,
    is the next session too: tests/test_session_bags.py.)"""
    m, log = small_log / "m.yaml", small_log / "run.log"
    state = tmp_path / "s.npz"
    assert main(["update", "--map", m, "--log", log, "--out", tmp_path / "a.yaml", "--state",
                 state, "--no-progress"]) == 0
    capsys.readouterr()
    grid = load_map(tmp_path / "a.yaml")
    grid.data[2, 2] = OCCUPIED                 # neither the map it started from nor made
    save_map(grid, tmp_path / "other.yaml")
    assert main(["update", "--map", tmp_path / "other.yaml", "--log", log, "--out",
                 tmp_path / "b.yaml", "--state", state, "--new-session", "--no-progress"]) == 0
    assert "a new session from the state" in capsys.readouterr().out
    refused(["update", "--map", m, "--log", log, "--out", tmp_path / "c.yaml",
             "--new-session", "--no-progress"], "--new-session", "give --state FILE too",
            inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "c.yaml"])


def test_a_state_is_refused_for_another_map_and_another_config(small_log, tmp_path, capsys):
    m, log = small_log / "m.yaml", small_log / "run.log"
    state = tmp_path / "s.npz"
    assert main(["update", "--map", m, "--log", log, "--out", tmp_path / "a.yaml", "--state",
                 state, "--no-progress"]) == 0
    other = reference_grid()
    other.data[2, 2] = OCCUPIED
    save_map(other, tmp_path / "other.yaml")
    refused(["update", "--map", tmp_path / "other.yaml", "--log", log, "--out",
             tmp_path / "b.yaml", "--state", state, "--no-progress"],
            "s.npz", "belongs to another map", "1 cells differ", inputs=tmp_path, capsys=capsys,
            outputs=[tmp_path / "b.yaml"])
    (tmp_path / "cfg.yaml").write_text("updater:\n  threshold: 5\n")
    refused(["update", "--map", m, "--log", log, "--out", tmp_path / "b.yaml", "--state",
             state, "--config", tmp_path / "cfg.yaml", "--no-progress"],
            "another updater configuration", "threshold", inputs=tmp_path, capsys=capsys,
            outputs=[tmp_path / "b.yaml"])
    (tmp_path / "bad.yaml").write_text("updater:\n  treshold: 5\n")
    refused(["update", "--map", m, "--log", log, "--out", tmp_path / "b.yaml", "--state",
             state, "--config", tmp_path / "bad.yaml", "--no-progress"],
            "did you mean 'threshold'", inputs=tmp_path, capsys=capsys,
            outputs=[tmp_path / "b.yaml"])
    raw = bytearray(state.read_bytes())
    raw[len(raw) // 2:len(raw) // 2 + 64] = bytes(64)           # 64 bytes overwritten
    state.write_bytes(bytes(raw))
    refused(["update", "--map", m, "--log", log, "--out", tmp_path / "b.yaml", "--state",
             state, "--no-progress"], "s.npz", inputs=tmp_path, capsys=capsys,
            outputs=[tmp_path / "b.yaml"])


# --- scenarios ----------------------------------------------------------------------------------
def scenario_edits():
    """(case, edit of the tiny room's dict, words of the refusal)."""
    def at(path, value):
        def edit(d):
            node = d
            for k in path[:-1]:
                node = node[k]
            node[path[-1]] = value
        return edit
    lidar = ("robot", "lidars", 0)
    yield "escaping name", at(("name",), "../escaped"), ("name", "cannot name files")
    yield "session name with a slash", at(("sessions", 1, "name"), "a/b"), ("cannot name files",)
    yield "fine resolution", at(("resolution",), 1e-4), ("resolution", "[0.01, 1]")
    yield "huge bounds", at(("world", "bounds"), [-1e6, -1e6, 1e6, 1e6]), ("[-5000, 5000]",)
    yield "wide world", at(("world", "bounds"), [0.0, 0.0, 4000.0, 4000.0]), \
        ("cells, more than the 64000000",)
    yield "one beam", at(lidar + ("beams",), 1), ("beams", "[2, 16384]")
    yield "ten million beams", at(lidar + ("beams",), 10_000_000), ("beams", "[2, 16384]")
    yield "lidar at 1 MHz", at(lidar + ("rate_hz",), 1e6), ("rate_hz", "[0.1, 100]")
    yield "physics at 1 MHz", at(("physics_hz",), 1e6), ("physics_hz", "[5, 1000]")
    yield "snail robot", at(("robot", "max_speed"), 1e-6), ("max_speed", "[0.01, 5]")
    yield "negative seed", at(("seed",), -1), ("seed", "must be in [0,")
    yield "a year of driving", at(("sessions", 1, "route"),
                                  [[7.0, 1.0], [7.0, 4.0]] * 5000), ("simulated days",)
    yield "a year of waiting", at(("sessions", 1, "max_duration"), 3.2e7), \
        ("max_duration", "[0, 86400]")


@pytest.mark.parametrize("case, edit, words", list(scenario_edits()),
                         ids=[c for c, _, _ in scenario_edits()])
def test_hostile_scenarios_are_refused_before_any_run(tmp_path, case, edit, words, capsys):
    d = copy.deepcopy(tiny_room_dict())
    edit(d)
    path = tmp_path / "s.yaml"
    path.write_text(yaml.safe_dump(d))
    refused(["run", path, "--out", tmp_path / "run", "--no-progress"], "s.yaml", *words,
            inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "run"])


def test_scenario_files_that_are_no_scenario(tmp_path, capsys):
    (tmp_path / "bin.yaml").write_bytes(os.urandom(512) + b"\x00")
    (tmp_path / "laughs.yaml").write_text(BILLION_LAUGHS)
    os.symlink("/dev/zero", tmp_path / "zero.yaml")
    for name, words in (("bin.yaml", ("binary",)), ("laughs.yaml", ("aliases",)),
                        ("zero.yaml", ("not a regular file",))):
        refused(["run", tmp_path / name, "--out", tmp_path / "run", "--no-progress"], name,
                *words, inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "run"])


# --- run options and run folders ------------------------------------------------------------
@pytest.mark.parametrize("args, words", [
    (["--sessions", "0"], ("sessions", "at least 1")),
    (["--sessions", "-3"], ("sessions", "at least 1")),
    (["--seed", "-1"], ("seed", "[0, 9223372036854775807]")),
])
def test_run_options_no_run_can_have(tmp_path, args, words, capsys):
    from tiny_room import write_tiny_room

    path = write_tiny_room(tmp_path / "room.yaml")
    refused(["run", path, "--out", tmp_path / "run", "--no-progress", *args], *words,
            inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "run"])


def test_out_naming_a_file_or_a_folder_in_use(tmp_path, capsys):
    from scenarios.checkpoint import RunFolderLock
    from tiny_room import write_tiny_room

    path = write_tiny_room(tmp_path / "room.yaml")
    (tmp_path / "afile").write_text("keep me")
    refused(["run", path, "--out", tmp_path / "afile", "--no-progress"], "afile",
            "not a folder", inputs=tmp_path, capsys=capsys)
    with RunFolderLock(tmp_path / "busy"):          # another run is writing there
        refused(["run", path, "--out", tmp_path / "busy", "--no-progress"], "busy",
                "another run is writing into this folder", f"pid {os.getpid()}",
                inputs=tmp_path, capsys=capsys, outputs=[tmp_path / "busy" / "report.md"])


def test_a_finished_run_is_never_overwritten_and_resume_checks_run_json(tmp_path, capsys):
    from tiny_room import write_tiny_room

    path = write_tiny_room(tmp_path / "room.yaml", max_duration=20.0)
    run = tmp_path / "run"
    with time_limit(LIMIT_S * 3):
        assert main(["run", path, "--out", run, "--sessions", "1", "--no-progress"]) == 0
    refused(["run", path, "--out", run, "--seed", "3", "--no-progress"], "holds a run already",
            "--resume", inputs=tmp_path, capsys=capsys)
    refused(["run", "--resume", run, "--seed", "3", "--no-progress"], "seed", inputs=tmp_path,
            capsys=capsys)
    manifest = run / "state" / "run.json"
    doc = json.loads(manifest.read_text())
    del doc["seed"]
    manifest.write_text(json.dumps(doc))
    refused(["run", "--resume", run, "--no-progress"], "run.json", "lacks seed",
            inputs=tmp_path, capsys=capsys)


def test_a_full_disk_mid_run_is_one_line_and_leaves_only_whole_files(tmp_path, capsys,
                                                                     monkeypatch):
    """The disk fills up at the k-th file the run writes: the run stops with one line, and
    every file left in its folder is complete (it parses), none half-written."""
    import errno

    import gridmap.atomic as atomic
    from tiny_room import write_tiny_room

    (tmp_path / "in").mkdir()
    path = write_tiny_room(tmp_path / "in" / "room.yaml", max_duration=20.0)
    real = atomic.os.fsync
    for k in (1, 4, 9):
        calls = [0]

        def fsync(fd, calls=calls, k=k):
            calls[0] += 1
            if calls[0] >= k:
                raise OSError(errno.ENOSPC, "No space left on device")
            return real(fd)
        monkeypatch.setattr(atomic.os, "fsync", fsync)
        run = tmp_path / f"run{k}"
        err = refused(["run", path, "--out", run, "--sessions", "2", "--no-progress"],
                      "No space left on device", inputs=tmp_path / "in", capsys=capsys)
        assert not [p for p in run.rglob("*") if ".tmp" in p.name]
        monkeypatch.setattr(atomic.os, "fsync", real)
        assert "Traceback" not in err
        for f in run.rglob("*"):
            if f.suffix == ".json":
                json.loads(f.read_text())
            elif f.suffix == ".yaml" and f.parent.name == "maps":
                load_map(f)


def test_maps_state_and_metrics_are_flushed_to_disk_before_and_after_the_rename(
        tmp_path, monkeypatch):
    """Durability against a power cut: each file is fsynced before it is renamed into place,
    and its folder after."""
    import stat

    import gridmap.atomic as atomic
    from updater import MapUpdater

    synced = []
    real = atomic.os.fsync

    def fsync(fd):
        st = os.fstat(fd)
        synced.append("folder" if stat.S_ISDIR(st.st_mode) else st.st_size)
        return real(fd)
    monkeypatch.setattr(atomic.os, "fsync", fsync)
    grid = reference_grid()
    save_map(grid, tmp_path / "m.yaml")                              # image, then YAML
    MapUpdater(grid, profile="paper").save(tmp_path / "s.npz")
    atomic.write_atomically(tmp_path / "metrics.json", "{}\n")
    sizes = [(tmp_path / n).stat().st_size for n in ("m.pgm", "m.yaml", "s.npz", "metrics.json")]
    assert synced == [sizes[0], "folder", sizes[1], "folder", sizes[2], "folder", sizes[3],
                      "folder"]


@pytest.mark.parametrize("section, key, value, words", [
    ("updater", "last_check_max_area", 1e300, ("last_check_max_area", "[0, 10000]")),
    ("updater", "virtual_to_measured_ratio", 1000000, ("virtual_to_measured_ratio", "[1, 16]")),
    ("updater", "window_deg", 1e9, ("window_deg", "[0, 45]")),
    ("pose_check", "fine_step_deg", 1e9, ("fine_step_deg", "[0.001, 45]")),
    ("pose_check", "coarse_steps", 10**6, ("coarse_steps", "[0, 50]")),
    ("localizer", "max_particles", 10**9, ("max_particles", "[1, 100000]")),
])
def test_config_values_that_would_hang_or_crash_are_refused_with_their_range(
        small_log, tmp_path, section, key, value, words, capsys):
    cfg = tmp_path / "cfg.yaml"
    cfg.write_text(yaml.safe_dump({section: {key: value}}))
    for args in (["run", "--config", cfg, "--out", tmp_path / "run", "--no-progress"],
                 ["update", "--config", cfg, "--map", small_log / "m.yaml", "--log",
                  small_log / "run.log", "--out", tmp_path / "o.yaml", "--no-progress"]):
        refused(args, "cfg.yaml", *words, inputs=tmp_path, capsys=capsys,
                outputs=[tmp_path / "run", tmp_path / "o.yaml"])


def test_a_damaged_state_file_is_refused_wherever_it_is_damaged(tmp_path):
    from updater import MapUpdater, UpdaterError

    MapUpdater(reference_grid()).save(tmp_path / "s.npz")
    raw = (tmp_path / "s.npz").read_bytes()
    kinds = set()
    for offset in range(0, len(raw) - 64, 16):
        damaged = bytearray(raw)
        damaged[offset:offset + 64] = bytes(64)
        (tmp_path / "d.npz").write_bytes(bytes(damaged))
        try:
            MapUpdater.load(tmp_path / "d.npz")
        except UpdaterError as e:
            kinds.add(str(e).split(":")[1].strip()[:30])
            assert "d.npz" in str(e) and "\n" not in str(e)
    assert kinds                      # and nothing but UpdaterError escaped


def test_a_laserscan_of_one_range_and_no_increment_is_skipped_and_counted(tmp_path, capsys):
    from gridmap import Pose2D, Scan
    from robotlogs.records import OdomRecord, ScanRecord, TransformRecord
    from robotlogs.rosbag import LASER_SCAN, BagWriter

    save_map(reference_grid(), tmp_path / "m.yaml")
    with BagWriter(tmp_path / "r.bag", "ros1") as w:
        for k in range(6):
            t = 1.7e9 + k
            w.write(OdomRecord(t, Pose2D(0.4 + 0.5 * k, 0.3, 0.0)))
            w.write_transforms([TransformRecord(t, "map", "odom", Pose2D(0.0, 0.0, 0.0))])
            if k == 3:          # one range, angle_increment 0: a scan no beam can be placed in
                w._put("/scan", LASER_SCAN, t, w._ts.types[LASER_SCAN](
                    header=w._header("/scan", t, "base_link"), angle_min=0.0, angle_max=0.0,
                    angle_increment=0.0, time_increment=0.0, scan_time=0.0, range_min=0.05,
                    range_max=10.0, ranges=np.array([1.0], np.float32),
                    intensities=np.zeros(0, np.float32)))
                continue
            w.write(ScanRecord(t, Scan(np.full(180, 0.3, np.float32), -1.57, 0.0175, 0.05,
                                       10.0, t), frame_id="base_link"))
    with time_limit(LIMIT_S):
        assert main(["update", "--map", tmp_path / "m.yaml", "--log", tmp_path / "r.bag",
                     "--out", tmp_path / "o.yaml", "--no-progress"]) == 0
    out = capsys.readouterr().out
    assert "5 of" in out or "of 5 scans" in out or "skipped" in out, out
    assert load_map(tmp_path / "o.yaml").shape == reference_grid().shape


@pytest.mark.filterwarnings("ignore:.*did not finish its route")
def test_a_run_with_bags_killed_mid_session_resumes_and_rewrites_its_unfinished_bag(tmp_path):
    from robotlogs.rosbag import bag_topics
    from scenarios.observers import Observers
    from scenarios.runner import RunOptions, run_scenario
    from scenarios.session_bags import SessionBagRecorder
    from tiny_room import write_tiny_room

    class Killed(BaseException):
        """Stands for SIGKILL: nothing after it runs."""

    class DiesInW2(SessionBagRecorder):
        def scan(self, msg, *args):
            super().scan(msg, *args)
            if msg.time > 5.0:
                raise Killed

    path = write_tiny_room(tmp_path / "room.yaml", max_duration=20.0)
    bags, run = tmp_path / "bags", tmp_path / "run"
    with pytest.raises(Killed):
        run_scenario(path, RunOptions(out=run, sessions=2, progress=False,
                                      observer=Observers(DiesInW2(bags))))
    assert not (bags / "W2.bag").exists() and (bags / ".partial-W2.bag").exists()
    recorder = SessionBagRecorder(bags)
    with time_limit(LIMIT_S * 3):
        run_scenario(None, RunOptions(out=run, resume=True, progress=False,
                                      observer=Observers(recorder)))
    assert recorder.paths["W2"] == bags / "W2.bag" and not (bags / ".partial-W2.bag").exists()
    assert bag_topics(bags / "W2.bag")["/scan"] == "sensor_msgs/msg/LaserScan"


def test_generate_never_writes_over_a_built_in_scenario_or_into_a_folder_name(tmp_path, capsys):
    from scenarios.catalog import find_scenario

    builtin = find_scenario("aws_small_warehouse")
    before = builtin.read_bytes()
    for out, words in ((builtin, "built-in scenario"), (tmp_path, "is a folder")):
        capsys.readouterr()
        assert main(["generate", "--seed", "3", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert words in err and len(err.strip().splitlines()) == 1
    assert builtin.read_bytes() == before
