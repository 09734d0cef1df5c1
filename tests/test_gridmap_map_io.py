"""map_server YAML + PGM files: round trips, the three modes, and every malformed file."""

import numpy as np
import pytest
import yaml

from gridmap import (FREE, OCCUPIED, UNKNOWN, GridError, MapFileError, OccupancyGrid, load_map,
                     save_map)
from gridmap.map_io import read_map_values, read_pgm


def write_map(folder, pixels, *, magic="P5", maxval=255, header=None, **keys):
    """A map with ``pixels`` in image rows (row 0 = top) in m.pgm; ``keys`` override the YAML
    (None drops a key). Returns the YAML path."""
    pixels = np.asarray(pixels)
    h, w = pixels.shape
    head = header if header is not None else f"{magic}\n# test\n{w} {h}\n{maxval}\n".encode()
    if magic == "P5" and header is None:
        body = pixels.astype(">u2" if maxval > 255 else np.uint8).tobytes()
    elif header is None:
        body = "\n".join(" ".join(str(v) for v in row) for row in pixels).encode() + b"\n"
    else:
        body = pixels.astype(np.uint8).tobytes()
    (folder / "m.pgm").write_bytes(head + body)
    doc = {"image": "m.pgm", "resolution": 0.05, "origin": [-1.0, 2.0, 0.0], "negate": 0,
           "occupied_thresh": 0.65, "free_thresh": 0.196}
    doc.update(keys)
    doc = {k: v for k, v in doc.items() if v is not None}
    path = folder / "m.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


# Image rows, top first: 0 black (occupied), 254 white (free), 205 grey (unknown).
PIXELS = np.array([[0, 254, 205],
                   [254, 254, 0]])
# The same as grid rows: row 0 = bottom of the image.
CELLS = np.array([[FREE, FREE, OCCUPIED],
                  [OCCUPIED, FREE, UNKNOWN]], np.int8)


@pytest.mark.parametrize("magic", ["P5", "P2"])
def test_load_trinary_flips_rows(tmp_path, magic):
    grid = load_map(write_map(tmp_path, PIXELS, magic=magic))
    assert np.array_equal(grid.data, CELLS)
    assert grid.resolution == 0.05
    assert grid.origin == (-1.0, 2.0)
    # Cell (0, 2) is the image's bottom-right pixel, at x in [-0.9, -0.85), y in [2.0, 2.05).
    assert grid.world_to_cell(-0.87, 2.01) == (0, 2)


def test_sixteen_bit_pgm(tmp_path):
    grid = load_map(write_map(tmp_path, PIXELS.astype(np.int64) * 257, maxval=65535))
    assert np.array_equal(grid.data, CELLS)


def test_round_trip(tmp_path):
    rng = np.random.default_rng(5)
    data = rng.choice(np.array([FREE, OCCUPIED, UNKNOWN], np.int8), size=(37, 53))
    grid = OccupancyGrid(data, 0.05, origin=(-6.85 - 0.13, 1e-3 / 3))
    yaml_path, pgm_path = save_map(grid, tmp_path / "sub.yaml")
    assert pgm_path == tmp_path / "sub.pgm"
    back = load_map(yaml_path)
    assert np.array_equal(back.data, grid.data)
    assert back.origin == grid.origin and back.resolution == grid.resolution
    # What map_server needs, in the form map_saver writes it.
    doc = yaml.safe_load(yaml_path.read_text())
    assert doc["image"] == "sub.pgm" and doc["mode"] == "trinary" and doc["negate"] == 0
    assert doc["origin"][2] == 0.0
    raw = pgm_path.read_bytes()
    assert raw.startswith(b"P5\n")
    pixels, maxval = read_pgm(pgm_path)
    assert maxval == 255 and set(np.unique(pixels).tolist()) == {0, 205, 254}
    assert np.array_equal(pixels[::-1] == 0, data == OCCUPIED)
    # No temporary file left beside the map.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sub.pgm", "sub.yaml"]


def test_save_overwrites_and_thresholds_graded_cells(tmp_path):
    save_map(OccupancyGrid.empty(4, 3, 0.1), tmp_path / "a.yaml")
    graded = np.array([[0, 25, 26, 64], [65, 100, -1, 50]], np.int8)
    save_map(OccupancyGrid(graded, 0.1), tmp_path / "a.yaml")
    back = load_map(tmp_path / "a.yaml")
    assert back.data.tolist() == [[0, 0, -1, -1], [100, 100, -1, -1]]


def test_negate(tmp_path):
    grid = load_map(write_map(tmp_path, 255 - PIXELS, negate=1))
    assert np.array_equal(grid.data, CELLS)


def test_thresholds_are_strict(tmp_path):
    # occ = (255 - v) / 255: 89 -> 0.651 occupied, 90 -> 0.647 unknown, 205 -> 0.196 unknown,
    # 206 -> 0.192 free (occupied_thresh 0.65, free_thresh 0.196).
    grid = load_map(write_map(tmp_path, [[89, 90, 205, 206]]))
    assert grid.data.tolist() == [[OCCUPIED, UNKNOWN, UNKNOWN, FREE]]


def test_scale_mode(tmp_path):
    path = write_map(tmp_path, [[0, 128, 30, 254]], mode="scale", occupied_thresh=0.9,
                     free_thresh=0.1)
    values, meta = read_map_values(path)
    # 128: occ = 127/255 = 0.498; ratio (0.498 - 0.1) / 0.8 = 0.4975 -> 99 * 0.4975 = 49.
    # 30: occ = 0.882 -> ratio 0.978 -> 96.
    assert meta.mode == "scale"
    assert values.tolist() == [[100, 49, 96, 0]]
    # The trinary grid keeps only what the file's thresholds call free or occupied.
    assert load_map(path).data.tolist() == [[OCCUPIED, UNKNOWN, UNKNOWN, FREE]]


def test_raw_mode(tmp_path):
    path = write_map(tmp_path, [[0, 30, 100, 101, 255]], mode="raw")
    values, _ = read_map_values(path)
    assert values.tolist() == [[0, 30, 100, UNKNOWN, UNKNOWN]]
    # Raw values are percent: 30 % is below neither threshold's side -> unknown.
    assert load_map(path).data.tolist() == [[FREE, UNKNOWN, OCCUPIED, UNKNOWN, UNKNOWN]]


def test_image_path_relative_to_yaml_and_absolute(tmp_path, monkeypatch):
    sub = tmp_path / "maps"
    sub.mkdir()
    path = write_map(sub, PIXELS)
    monkeypatch.chdir(tmp_path)  # not the YAML's folder
    assert np.array_equal(load_map("maps/m.yaml").data, CELLS)
    doc = yaml.safe_load(path.read_text())
    doc["image"] = str(sub / "m.pgm")
    path.write_text(yaml.safe_dump(doc))
    assert np.array_equal(load_map(path).data, CELLS)


def test_png_image(tmp_path):
    from PIL import Image

    Image.fromarray(PIXELS.astype(np.uint8)).save(tmp_path / "m.png")
    path = write_map(tmp_path, PIXELS)
    doc = yaml.safe_load(path.read_text())
    doc["image"] = "m.png"
    path.write_text(yaml.safe_dump(doc))
    assert np.array_equal(load_map(path).data, CELLS)


# --- malformed files ---------------------------------------------------------------------------

def expect_error(path, *words):
    with pytest.raises(MapFileError) as info:
        load_map(path)
    msg = str(info.value)
    for w in words:
        assert w in msg, msg
    assert isinstance(info.value, GridError)
    return msg


def test_missing_yaml(tmp_path):
    expect_error(tmp_path / "none.yaml", "none.yaml", "not found")


def test_missing_image(tmp_path):
    path = write_map(tmp_path, PIXELS)
    (tmp_path / "m.pgm").unlink()
    expect_error(path, "m.yaml", "m.pgm", "not found")


@pytest.mark.parametrize("header, problem", [
    (b"P6\n3 2\n255\n", "magic"),
    (b"JUNK", "magic"),
    (b"P5\n3\n", "height"),
    (b"P5\n3 x2\n255\n", "height"),
    (b"P5\n0 2\n255\n", "size"),
    (b"P5\n3 2\n70000\n", "maxval"),
    (b"P5\n3 2\n255", "whitespace"),
])
def test_bad_header(tmp_path, header, problem):
    path = write_map(tmp_path, PIXELS, header=header)
    msg = expect_error(path, "m.pgm", "bad PGM header", problem)
    assert "\n" not in msg


@pytest.mark.parametrize("magic", ["P5", "P2"])
def test_truncated_pixels(tmp_path, magic):
    path = write_map(tmp_path, PIXELS, magic=magic)
    raw = (tmp_path / "m.pgm").read_bytes()
    (tmp_path / "m.pgm").write_bytes(raw[:-3])
    expect_error(path, "m.pgm", "truncated pixel data")


def test_pixel_above_maxval(tmp_path):
    expect_error(write_map(tmp_path, [[0, 200]], magic="P2", maxval=100), "m.pgm", "outside 0..100")


@pytest.mark.parametrize("resolution", [0, -0.05, 1e-200, 1e-160, 1e-4, 1e300, 11.0])
def test_resolution_outside_what_a_map_can_have(tmp_path, resolution):
    expect_error(write_map(tmp_path, PIXELS, resolution=resolution), "m.yaml",
                 "resolution must be in [0.001, 10] m/cell", repr(resolution))


def test_non_zero_yaw(tmp_path):
    expect_error(write_map(tmp_path, PIXELS, origin=[0.0, 0.0, 0.3]), "m.yaml", "yaw", "0.3")


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "negate", "occupied_thresh",
                                 "free_thresh"])
def test_missing_key(tmp_path, key):
    expect_error(write_map(tmp_path, PIXELS, **{key: None}), "m.yaml", "missing key", key)


@pytest.mark.parametrize("keys, words", [
    ({"origin": [0.0, 0.0]}, ("origin", "[x, y, yaw]")),
    ({"origin": [0.0, "a", 0.0]}, ("origin[1]",)),
    ({"resolution": "fine"}, ("resolution", "number")),
    ({"mode": "colour"}, ("mode", "trinary")),
    ({"negate": 2}, ("negate",)),
    ({"free_thresh": 0.9}, ("free_thresh", "occupied_thresh")),
])
def test_bad_values(tmp_path, keys, words):
    expect_error(write_map(tmp_path, PIXELS, **keys), "m.yaml", *words)


def test_not_yaml_and_not_a_mapping(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("image: [unclosed\n")
    expect_error(path, "m.yaml", "not valid YAML")
    path.write_text("- just\n- a list\n")
    expect_error(path, "m.yaml", "mapping")


def test_save_refuses_pgm_name(tmp_path):
    with pytest.raises(MapFileError, match="m.pgm"):
        save_map(OccupancyGrid.empty(2, 2, 0.1), tmp_path / "m.pgm")


def test_trinary_image_is_the_saved_image_north_up(tmp_path):
    from gridmap.map_io import PIXEL_FREE, PIXEL_OCCUPIED, PIXEL_UNKNOWN, trinary_image

    data = np.array([[FREE, OCCUPIED, UNKNOWN], [OCCUPIED, FREE, FREE]], np.int8)
    grid = OccupancyGrid(data, 0.05, (0.0, 0.0))
    img = trinary_image(grid)
    # grid row 0 is the lowest y, image row 0 the top
    assert img.tolist() == [[PIXEL_OCCUPIED, PIXEL_FREE, PIXEL_FREE],
                            [PIXEL_FREE, PIXEL_OCCUPIED, PIXEL_UNKNOWN]]
    assert (PIXEL_OCCUPIED, PIXEL_UNKNOWN, PIXEL_FREE) == (0, 205, 254)
    _, pgm = save_map(grid, tmp_path / "m.yaml")
    assert pgm.read_bytes().endswith(img.tobytes())


def test_a_map_reached_through_a_link_loads_wherever_its_image_was_put(tmp_path):
    import os

    for sub in ("a", "b", "c"):
        (tmp_path / sub).mkdir()
    free = OccupancyGrid(np.zeros((4, 5), np.int8), 0.05)
    save_map(free, tmp_path / "b/real.yaml")                  # image beside the real file
    os.symlink(tmp_path / "b/real.yaml", tmp_path / "a/link.yaml")
    assert np.array_equal(load_map(tmp_path / "a/link.yaml").data, free.data)
    walls = OccupancyGrid(np.full((4, 5), 100, np.int8), 0.05)
    os.symlink(tmp_path / "c/target.yaml", tmp_path / "a/out.yaml")
    save_map(walls, tmp_path / "a/out.yaml")                  # image beside the link, as map_saver
    assert (tmp_path / "a/out.pgm").exists() and (tmp_path / "c/target.yaml").exists()
    assert np.array_equal(load_map(tmp_path / "a/out.yaml").data, walls.data)
