"""Properties that must hold for any input (hypothesis, derandomized so CI is reproducible):
ray casting, map metrics, map file round trips, and hostile map files and CARMEN logs, which may
only ever raise the documented errors (MapFileError / GridError, LogError)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from gridmap import (FREE, OCCUPIED, UNKNOWN, GridError, MapFileError, OccupancyGrid, Pose2D,
                     load_map, save_map)
from gridmap.metrics import compare_maps, opdf_one_way
from gridmap.raycast import cast_rays
from robotlogs.carmen import IGNORED, parse_carmen, read_carmen
from robotlogs.records import LogError

SETTINGS = dict(derandomize=True, deadline=None, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

cells = st.sampled_from([FREE, OCCUPIED, UNKNOWN])


def grids(min_side=1, max_side=24):
    return st.integers(min_side, max_side).flatmap(lambda h: st.integers(min_side, max_side)
                                                   .flatmap(lambda w: arrays(np.int8, (h, w),
                                                                             elements=cells)))


# --- ray casting -----------------------------------------------------------------------------
@settings(max_examples=150, **SETTINGS)
@given(grids(4, 30), st.floats(0.0, 1.0), st.floats(0.0, 1.0), st.floats(-math.pi, math.pi),
       st.floats(0.05, 3.0), st.booleans())
def test_cast_rays_ends_where_the_first_blocking_cell_begins(data, fx, fy, theta, max_range,
                                                             block_unknown):
    res = 0.1
    grid = OccupancyGrid(data, res, (-0.3, 0.7))
    x0, y0, x1, y1 = grid.extent()
    pose = Pose2D(x0 + fx * (x1 - x0) * 0.999, y0 + fy * (y1 - y0) * 0.999, theta)
    angles = np.linspace(-math.pi, math.pi, 37)
    r = cast_rays(grid, pose, angles, max_range, block_unknown)
    assert r.shape == angles.shape
    assert np.all(np.isinf(r) | ((r >= 0) & (r <= max_range + 1e-9)))
    blocking = (data == OCCUPIED) | ((data == UNKNOWN) if block_unknown else False)
    for a, d in zip(angles + theta, r):
        # no blocking cell strictly before the end (sampled a hair short of each cell crossing)
        n = int(math.ceil((d if np.isfinite(d) else max_range) / (0.2 * res)))
        for t in np.linspace(0.0, (d if np.isfinite(d) else max_range), n + 1)[:-1]:
            t = max(t - 1e-6, 0.0)
            row, col = grid.world_to_cell(pose.x + t * math.cos(a), pose.y + t * math.sin(a))
            if grid.contains(row, col):
                assert not blocking[row, col] or (t < 1e-6 and d == 0.0)
        if d == 0.0:
            # the beam starts in a blocking cell (which the step past the end may leave), or
            # on the border heading out of the map when unknown blocks
            row, col = grid.world_to_cell(pose.x, pose.y)
            on_border = min(abs(pose.x - x0), abs(pose.y - y0)) < 1e-9
            assert (grid.contains(row, col) and blocking[row, col]) or \
                (block_unknown and on_border)
        elif np.isfinite(d):
            # just past the end: a blocking cell, or (block_unknown) the outside of the map
            row, col = grid.world_to_cell(pose.x + (d + 1e-6) * math.cos(a),
                                          pose.y + (d + 1e-6) * math.sin(a))
            inside = bool(grid.contains(row, col))
            assert (inside and blocking[row, col]) or (block_unknown and not inside) or \
                _on_a_corner(pose, a, d, grid)


def _on_a_corner(pose, a, d, grid) -> bool:
    """The end point lies on a grid line crossing, where which cell comes next is rounding."""
    gx = (pose.x + d * math.cos(a) - grid.origin[0]) / grid.resolution
    gy = (pose.y + d * math.sin(a) - grid.origin[1]) / grid.resolution
    return abs(gx - round(gx)) < 1e-6 and abs(gy - round(gy)) < 1e-6


@settings(max_examples=100, **SETTINGS)
@given(grids(4, 24), st.data())
def test_more_obstacles_never_lengthen_a_ray(data, draw):
    grid = OccupancyGrid(data, 0.05)
    more = data.copy()
    mask = draw.draw(arrays(np.bool_, data.shape))
    more[mask] = OCCUPIED
    pose = Pose2D(draw.draw(st.floats(0, data.shape[1] * 0.05)),
                  draw.draw(st.floats(0, data.shape[0] * 0.05)),
                  draw.draw(st.floats(-math.pi, math.pi)))
    angles = np.linspace(-3.0, 3.0, 25)
    a = cast_rays(grid, pose, angles, 2.0)
    b = cast_rays(grid.with_data(more), pose, angles, 2.0)
    assert np.all(b <= a)


# --- metrics ---------------------------------------------------------------------------------
@settings(max_examples=200, **SETTINGS)
@given(st.integers(2, 20).flatmap(lambda h: st.integers(2, 20).flatmap(
    lambda w: st.tuples(arrays(np.int8, (h, w), elements=cells),
                        arrays(np.int8, (h, w), elements=cells)))))
def test_metrics_are_symmetric_bounded_and_100_for_identical_maps(pair):
    a, b = pair
    uniform = a.min() == a.max() or b.min() == b.max()
    if uniform:
        with pytest.raises(GridError, match="undefined"):
            compare_maps(a, b)
        return
    ab, ba = compare_maps(a, b), compare_maps(b, a)
    for key in ("cc", "ms", "opdf"):
        assert ab[key] == pytest.approx(ba[key], abs=1e-9)
    assert -100 - 1e-9 <= ab["cc"] <= 100 + 1e-9
    assert 0 <= ab["ms"] <= 100 and 0 <= ab["opdf"] <= 100
    assert 0 <= opdf_one_way(a, b) <= 100
    same = compare_maps(a, a)
    assert same["cc"] == pytest.approx(100) and same["ms"] == 100 and same["opdf"] == 100


# --- file round trips --------------------------------------------------------------------------
@settings(max_examples=60, **SETTINGS)
@given(grids(1, 40), st.floats(1e-3, 10.0), st.floats(-1e4, 1e4), st.floats(-1e4, 1e4))
def test_save_then_load_gives_the_same_grid(tmp_path_factory, data, resolution, ox, oy):
    folder = tmp_path_factory.mktemp("rt")
    grid = OccupancyGrid(data, resolution, (ox, oy))
    save_map(grid, folder / "m.yaml")
    back = load_map(folder / "m.yaml")
    assert back.resolution == grid.resolution and back.origin == grid.origin
    assert back.data.dtype == np.int8 and (back.data == grid.data).all()


# --- hostile map files ----------------------------------------------------------------------------
scalars = st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20),
                    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12))
values = st.recursive(scalars, lambda c: st.lists(c, max_size=4), max_leaves=6)
KEYS = ["image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode"]


@st.composite
def map_yaml(draw):
    """A map_server YAML: right half of the time, else with keys dropped, replaced or added,
    and now and then not YAML at all."""
    doc = {"image": "m.pgm", "resolution": 0.05, "origin": [0.0, 0.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    if draw(st.booleans()):
        for key in draw(st.lists(st.sampled_from(KEYS), min_size=1, max_size=3)):
            if draw(st.booleans()):
                doc.pop(key, None)
            else:
                doc[key] = draw(values)
        if draw(st.booleans()):
            doc[draw(st.text(min_size=1, max_size=8))] = draw(values)
    text = yaml.safe_dump(doc)
    return draw(st.text(max_size=60)) if draw(st.integers(0, 9)) == 0 else text


@st.composite
def pgm_bytes(draw):
    """A PGM image: right half of the time, else with its header's fields and its pixel bytes
    each possibly wrong or cut."""
    w, h = draw(st.integers(1, 6)), draw(st.integers(1, 6))
    good = draw(st.booleans())
    magic = b"P5" if good else draw(st.sampled_from([b"P5", b"P2", b"P6", b"", b"P"]))
    if not good:
        w, h = draw(st.integers(-2, 6)), draw(st.integers(-2, 6))
    maxval = 255 if good else draw(st.sampled_from([255, 65535, 100, 0, 70000, -1]))
    sep = b"\n" if good else draw(st.sampled_from([b"\n", b" ", b"\n# comment\n", b""]))
    head = magic + b"\n" + f"{w} {h}".encode() + sep + str(maxval).encode() + b"\n"
    if magic == b"P2":
        body = " ".join(str(draw(st.integers(-5, 70000))) for _ in
                        range(draw(st.integers(0, 40)))).encode()
    else:
        size = max(w, 0) * max(h, 0) * (2 if maxval > 255 else 1)
        body = draw(st.binary(min_size=size, max_size=size)) if good else \
            draw(st.binary(max_size=80))
    raw = head + body
    return raw if good else raw[:draw(st.integers(0, len(raw)))]


@settings(max_examples=300, **SETTINGS)
@given(map_yaml(), pgm_bytes())
def test_hostile_map_files_raise_only_map_file_errors(tmp_path_factory, text, image):
    folder = tmp_path_factory.mktemp("hostile")
    (folder / "m.yaml").write_text(text)
    (folder / "m.pgm").write_bytes(image)
    try:
        grid = load_map(folder / "m.yaml")
    except MapFileError as e:
        assert "\n" not in str(e) and "m." in str(e)
    except GridError:
        pass                                      # a grid the file describes is not usable
    else:
        assert isinstance(grid, OccupancyGrid) and grid.data.dtype == np.int8
        assert set(np.unique(grid.data)) <= {FREE, OCCUPIED, UNKNOWN}


# --- hostile CARMEN logs --------------------------------------------------------------------------
NAMES = ["FLASER", "RLASER", "ROBOTLASER1", "ROBOTLASER2", "ODOM", "TRUEPOS", "PARAM",
         sorted(IGNORED)[0], "BOGUS", "#"]
tokens = st.one_of(st.integers(-3, 400).map(str), st.floats(allow_nan=True).map(repr),
                   st.sampled_from(["nan", "inf", "-inf", "1e309", "81.83", "host", "", "0x1f",
                                    "99999999999999999999"]),
                   st.text(max_size=5))


def _numbers(draw, n, low=-10.0, high=90.0):
    return [f"{draw(st.floats(low, high)):.3f}" for _ in range(n)]


@st.composite
def carmen_line(draw):
    """A well-formed line of one of the kinds read, then (most of the time) mangled: words
    replaced, dropped or added, which turns counts, fields and timestamps wrong."""
    name = draw(st.sampled_from(NAMES))
    t = [f"{draw(st.floats(0, 1e4)):.3f}", "host", "0.0"]
    if name in ("FLASER", "RLASER"):
        n = draw(st.integers(0, 8))
        words = [name, str(n)] + _numbers(draw, n, 0.0, 90.0) + _numbers(draw, 6) + t
    elif name.startswith("ROBOTLASER"):
        n, m = draw(st.integers(0, 6)), draw(st.integers(0, 3))
        inc = draw(st.floats(0.001, 0.5))
        words = ([name, "0", f"{-inc * n / 2:.4f}", f"{inc * max(n - 1, 0):.4f}", f"{inc:.4f}",
                  "20.0", "0.01", "0", str(n)] + _numbers(draw, n, 0.0, 30.0) + [str(m)]
                 + _numbers(draw, m) + _numbers(draw, 11) + t)
    elif name in ("ODOM", "TRUEPOS"):
        words = [name] + _numbers(draw, 6) + t
    else:
        words = [name] + draw(st.lists(tokens, max_size=6))
    for _ in range(draw(st.integers(0, 3))):
        k = draw(st.integers(0, len(words)))
        what = draw(st.sampled_from(["replace", "drop", "insert"]))
        if what == "insert" or k == len(words):
            words.insert(k, draw(tokens))
        elif what == "drop":
            del words[k]
        else:
            words[k] = draw(tokens)
    return " ".join(words)


@settings(max_examples=300, **SETTINGS)
@given(st.lists(carmen_line(), max_size=12))
def test_hostile_carmen_lines_raise_only_log_errors(lines):
    log = parse_carmen(lines, source="h.log")               # lenient: skips and counts
    assert len(log.records) + log.stats.total_skipped + sum(log.stats.ignored.values()) \
        <= len(lines)
    times = [r.time for r in log.records]
    assert times == sorted(times) and all(math.isfinite(t) for t in times)
    for r in log.records:
        scan = getattr(r, "scan", None)
        if scan is not None:
            # a bad reading is an invalid beam (NaN), as in a LaserScan; never a negative range
            assert scan.ranges.dtype == np.float32 and not (scan.ranges < 0).any()
    try:
        parse_carmen(lines, source="h.log", strict=True)
    except LogError as e:
        assert str(e).startswith("h.log, line ")


@settings(max_examples=60, **SETTINGS)
@given(st.binary(max_size=300))
def test_hostile_carmen_bytes_raise_only_log_errors(tmp_path_factory, raw):
    path = tmp_path_factory.mktemp("carmen") / "x.log"
    path.write_bytes(raw)
    try:
        read_carmen(path)
    except LogError as e:
        assert "x.log" in str(e)


# --- hostile PNG maps -----------------------------------------------------------------------------
PNG_MODES = ["L", "LA", "RGB", "RGBA", "P", "1", "I;16"]


@st.composite
def png_bytes(draw):
    """An image in any of the modes a map might come in, saved as PNG, then (sometimes) cut
    short or with bytes overwritten."""
    import io

    from PIL import Image

    mode = draw(st.sampled_from(PNG_MODES))
    w, h = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    top = 65535 if mode == "I;16" else 255
    bands = {"LA": 2, "RGB": 3, "RGBA": 4}.get(mode, 1)
    shape = (h, w) if bands == 1 else (h, w, bands)
    values = draw(arrays(np.int64, shape, elements=st.integers(0, top)))
    if mode == "I;16":
        im = Image.fromarray(values.astype(np.uint16))
    elif mode in ("P", "1"):
        im = Image.fromarray(values.astype(np.uint8), "L").convert(mode)
    else:
        im = Image.fromarray(values.astype(np.uint8), mode)
    out = io.BytesIO()
    im.save(out, "PNG")
    raw = bytearray(out.getvalue())
    damage = draw(st.sampled_from(["none", "cut", "overwrite"]))
    if damage == "cut":
        raw = raw[:draw(st.integers(0, len(raw)))]
    elif damage == "overwrite":
        k = draw(st.integers(0, len(raw) - 1))
        raw[k:k + 8] = draw(st.binary(min_size=1, max_size=8))
    return bytes(raw), damage == "none"


@settings(max_examples=200, **SETTINGS)
@given(png_bytes(), st.sampled_from(["trinary", "scale", "raw"]), st.booleans())
def test_hostile_png_maps_raise_only_map_file_errors(tmp_path_factory, image, mode, negate):
    raw, intact = image
    folder = tmp_path_factory.mktemp("png")
    (folder / "m.png").write_bytes(raw)
    (folder / "m.yaml").write_text(f"image: m.png\nresolution: 0.05\norigin: [0.0, 0.0, 0.0]\n"
                                   f"negate: {int(negate)}\noccupied_thresh: 0.65\n"
                                   f"free_thresh: 0.196\nmode: {mode}\n")
    try:
        grid = load_map(folder / "m.yaml")
    except MapFileError as e:
        assert "\n" not in str(e) and "m." in str(e)
        assert not intact, f"an intact PNG was refused: {e}"
    else:
        assert set(np.unique(grid.data)) <= {FREE, OCCUPIED, UNKNOWN}


# --- hostile scenario files -----------------------------------------------------------------------
@st.composite
def scenario_mutation(draw):
    """The tiny room's scenario with one value somewhere replaced by a hostile one."""
    from tiny_room import tiny_room_dict

    doc = tiny_room_dict()
    paths = []

    def walk(node, path):
        paths.append(path)
        if isinstance(node, dict):
            for k, v in node.items():
                walk(v, path + (k,))
        elif isinstance(node, list):
            for i, v in enumerate(node):
                walk(v, path + (i,))
    walk(doc, ())
    path = draw(st.sampled_from(paths[1:]))
    node = doc
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = draw(st.one_of(values, st.floats(-1e12, 1e12), st.integers(-10**9, 10**9),
                                    st.sampled_from([1e-300, 1e300, 0, -1, "../x", [], {}])))
    return doc


@settings(max_examples=150, **SETTINGS)
@given(scenario_mutation())
def test_hostile_scenarios_raise_only_scenario_errors(doc):
    import sim

    try:
        scn = sim.scenario_from_dict(doc, "h.yaml")
    except sim.ScenarioError as e:
        assert "\n" not in str(e) and str(e).startswith("h.yaml")
    else:
        assert scn.resolution >= 0.01 and all(ld.beams >= 2 for ld in scn.robot.lidars)
