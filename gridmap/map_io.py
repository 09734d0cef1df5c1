"""ROS map_server map files: a YAML description beside a PGM image.

The YAML keys are those of map_server: ``image`` (path relative to the YAML file, or absolute),
``resolution`` [m/cell], ``origin`` [x, y, yaw] (the lower-left corner of the image in the map
frame), ``negate``, ``occupied_thresh``, ``free_thresh`` and the optional ``mode`` (``trinary``,
``scale`` or ``raw``; default ``trinary``).

Pixel interpretation follows ROS 1 map_server. A pixel's darkness ``occ = 1 - value / maxval``
(``value / maxval`` with ``negate``) is occupied above ``occupied_thresh`` and free below
``free_thresh``; in between it is unknown in ``trinary`` mode and a graded 1..99 in ``scale``
mode. In ``raw`` mode the 8-bit pixel value is the cell value itself (0..100, anything else
unknown). :func:`read_map_values` returns those map_server values; :func:`load_map` returns the
trinary grid this project works with: a graded ``scale`` cell is unknown, and a ``raw`` value,
an occupancy in percent, is compared with the file's thresholds.

Image row 0 is the top of the picture, the highest y; grid row 0 is the lowest y, so rows are
flipped on the way in and out. Maps are saved as trinary P5 images the way map_saver writes
them (free 254, occupied 0, unknown 205, ``free_thresh`` 0.196, ``occupied_thresh`` 0.65).
"""

from __future__ import annotations

import math
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .atomic import write_atomically
from .cells import FREE, OCCUPIED, UNKNOWN
from .files import FileInputError, check_regular_file, load_yaml
from .types import GridError, OccupancyGrid

MODES = ("trinary", "scale", "raw")
# What a map can be: 1 mm to 10 m cells, an origin within 1000 km, at most 64 M cells (8000 x
# 8000, 400 m at 5 cm; the updater holds a few bytes per cell). Beyond these a map is a
# mistake, and reading it would only fill memory.
MIN_RESOLUTION, MAX_RESOLUTION = 1e-3, 10.0
MAX_ORIGIN = 1e6
MAX_CELLS = 64_000_000
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")

# What map_saver writes: these grey levels and thresholds read back as the same three states
# (205 gives occ = 50/255 = 0.19608, just above free_thresh, so it stays unknown). The one place
# the project defines them; pictures of a map in these grey levels use ``trinary_image``.
PIXEL_FREE = 254
PIXEL_OCCUPIED = 0
PIXEL_UNKNOWN = 205
SAVE_OCCUPIED_THRESH = 0.65
SAVE_FREE_THRESH = 0.196


class MapFileError(GridError):
    """A map file that cannot be read or written; the message names the file and the problem."""


@dataclass(frozen=True)
class MapMetadata:
    """The YAML half of a map_server map, validated."""

    image: Path                  # absolute path of the image
    resolution: float            # [m/cell]
    origin: tuple[float, float]  # lower-left corner of the image [m]; yaw is always 0
    negate: bool
    occupied_thresh: float
    free_thresh: float
    mode: str = "trinary"


# --- reading -----------------------------------------------------------------------------------

def load_map(path) -> OccupancyGrid:
    """Load a map_server map (YAML + image) as a trinary :class:`OccupancyGrid`.

    Raises :class:`MapFileError` naming the file for a missing or malformed YAML key, a missing
    image, a bad image header, truncated pixel data, a non-positive resolution or a non-zero
    origin yaw.
    """
    values, meta = read_map_values(path)
    if meta.mode == "trinary":
        data = values
    elif meta.mode == "scale":
        # 1..99 marks pixels between the two thresholds: neither clearly free nor occupied.
        data = np.where((values > FREE) & (values < OCCUPIED), UNKNOWN, values).astype(np.int8)
    else:
        # Raw values are occupancy in percent: thresholded with the file's own thresholds.
        p = values.astype(np.float64) / 100.0
        data = np.full(values.shape, UNKNOWN, np.int8)
        known = values >= 0
        data[known & (p > meta.occupied_thresh)] = OCCUPIED
        data[known & (p < meta.free_thresh)] = FREE
    return OccupancyGrid(data, meta.resolution, meta.origin)


def read_map_values(path) -> tuple[np.ndarray, MapMetadata]:
    """The cell values map_server would publish for this map (int8, grid rows: row 0 = lowest y)
    and the validated metadata. Values are 0..100 or -1, graded in ``scale`` and ``raw`` modes."""
    meta = read_map_yaml(path)
    pixels, maxval, opaque = _read_image(meta.image, path)
    values = _pixels_to_values(pixels, maxval, meta)
    if opaque is not None and meta.mode == "scale":     # map_server: graded and see-through
        values[~opaque & (values > FREE) & (values < OCCUPIED)] = UNKNOWN
    # Image row 0 is the top (highest y); grid row 0 is the bottom.
    return values[::-1], meta


def _beside(path: Path, image: str) -> Path:
    """A relative image: beside the YAML as named, as map_server and ``save_map`` place it
    (a YAML reached through a link has its image beside the link); else beside the file the
    link points at."""
    named = path.absolute().parent / image
    if named.exists():
        return named
    real = path.resolve().parent / image
    return real if real.exists() else named


def read_map_yaml(path) -> MapMetadata:
    """Read and validate a map_server YAML file."""
    path = Path(path)
    try:
        doc = load_yaml(path, "map file", MapFileError)
    except FileNotFoundError:
        raise MapFileError(f"{path}: map file not found") from None
    except FileInputError as e:
        raise MapFileError(str(e)) from None
    if not isinstance(doc, dict):
        raise MapFileError(f"{path}: expected a mapping of map_server keys, "
                           f"got {type(doc).__name__}")
    missing = [k for k in REQUIRED_KEYS if k not in doc]
    if missing:
        raise MapFileError(f"{path}: missing key(s) {', '.join(missing)}")

    image = doc["image"]
    if not isinstance(image, str) or not image:
        raise MapFileError(f"{path}: key 'image' must be a file name, got {image!r}")
    image_path = Path(image) if os.path.isabs(image) else _beside(path, image)
    resolution = _number(path, "resolution", doc["resolution"])
    if not MIN_RESOLUTION <= resolution <= MAX_RESOLUTION:
        raise MapFileError(f"{path}: resolution must be in [{MIN_RESOLUTION:g}, "
                           f"{MAX_RESOLUTION:g}] m/cell, got {doc['resolution']!r}")
    origin = doc["origin"]
    if not isinstance(origin, (list, tuple)) or len(origin) != 3:
        raise MapFileError(f"{path}: key 'origin' must be [x, y, yaw], got {origin!r}")
    ox, oy, yaw = (_number(path, f"origin[{i}]", v) for i, v in enumerate(origin))
    if max(abs(ox), abs(oy)) > MAX_ORIGIN:
        raise MapFileError(f"{path}: origin must lie within {MAX_ORIGIN:g} m of 0, got "
                           f"[{ox:g}, {oy:g}]")
    if yaw != 0.0:
        raise MapFileError(f"{path}: origin yaw {yaw} is not zero; rotated maps are not supported")
    negate = doc["negate"]
    if negate not in (0, 1, True, False):
        raise MapFileError(f"{path}: key 'negate' must be 0 or 1, got {negate!r}")
    occ = _number(path, "occupied_thresh", doc["occupied_thresh"])
    free = _number(path, "free_thresh", doc["free_thresh"])
    if not (0.0 <= free <= occ <= 1.0):
        raise MapFileError(f"{path}: need 0 <= free_thresh <= occupied_thresh <= 1, got "
                           f"free_thresh={free}, occupied_thresh={occ}")
    mode = doc.get("mode", "trinary")
    if mode not in MODES:
        raise MapFileError(f"{path}: key 'mode' must be one of {', '.join(MODES)}, got {mode!r}")
    return MapMetadata(image_path, resolution, (ox, oy), bool(negate), occ, free, mode)


def read_pgm(path) -> tuple[np.ndarray, int]:
    """Read a binary (P5) or ASCII (P2) PGM image: (pixels as uint16 in image rows, maxval)."""
    path = Path(path)
    try:
        # two bytes a pixel at most, and a header
        check_regular_file(path, "image file", 2 * MAX_CELLS + 4096)
        raw = path.read_bytes()
    except FileNotFoundError:
        raise MapFileError(f"{path}: image file not found") from None
    except FileInputError as e:
        raise MapFileError(str(e)) from None
    except OSError as e:
        raise MapFileError(f"{path}: cannot read image ({e})") from None
    magic = raw[:2]
    if magic not in (b"P5", b"P2"):
        raise MapFileError(f"{path}: bad PGM header: magic number {magic!r}, "
                           "expected b'P5' or b'P2'")
    fields, pos = _header_fields(raw, path, 3)
    width, height, maxval = fields
    if width <= 0 or height <= 0:
        raise MapFileError(f"{path}: bad PGM header: image size {width} x {height}")
    _check_size(path, width, height)
    if not 0 < maxval < 65536:
        raise MapFileError(f"{path}: bad PGM header: maxval {maxval} not in 1..65535")
    n = width * height
    if magic == b"P5":
        # Exactly one whitespace byte separates the header from the pixels.
        body = raw[pos + 1:]
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype(np.uint8)
        if len(body) < n * dtype.itemsize:
            raise MapFileError(f"{path}: truncated pixel data: {len(body)} bytes for "
                               f"{width} x {height} pixels of {dtype.itemsize} byte(s)")
        pixels = np.frombuffer(body, dtype, count=n).astype(np.uint16)
    else:
        tokens = _strip_comments(raw[pos:]).split()
        if len(tokens) < n:
            raise MapFileError(f"{path}: truncated pixel data: {len(tokens)} values for "
                               f"{width} x {height} pixels")
        try:
            pixels = np.array([int(t) for t in tokens[:n]], dtype=np.int64)
        except ValueError:
            raise MapFileError(f"{path}: bad pixel data: non-integer value in P2 image") from None
        except OverflowError:   # a value beyond int64 is beyond any maxval too
            raise MapFileError(f"{path}: bad pixel data: values outside 0..{maxval}") from None
    if pixels.max(initial=0) > maxval or pixels.min(initial=0) < 0:
        raise MapFileError(f"{path}: bad pixel data: values outside 0..{maxval}")
    return pixels.astype(np.uint16).reshape(height, width), int(maxval)


def _header_fields(raw: bytes, path: Path, count: int) -> tuple[list[int], int]:
    """The ``count`` integers after the magic number, skipping whitespace and # comments;
    returns them and the offset of the byte after the last one."""
    fields = []
    pos = 2
    n = len(raw)
    while len(fields) < count:
        while pos < n and raw[pos:pos + 1].isspace():
            pos += 1
        if pos < n and raw[pos:pos + 1] == b"#":
            while pos < n and raw[pos:pos + 1] not in (b"\n", b"\r"):
                pos += 1
            continue
        start = pos
        while pos < n and raw[pos:pos + 1].isdigit():
            pos += 1
        if start == pos:
            what = ("width", "height", "maxval")[len(fields)]
            got = raw[start:start + 8]
            found = f"got {got!r}" if got else "the file ends"
            raise MapFileError(f"{path}: bad PGM header: expected {what}, {found}")
        fields.append(int(raw[start:pos]))
    if pos >= len(raw) or not raw[pos:pos + 1].isspace():
        raise MapFileError(f"{path}: bad PGM header: no whitespace after maxval")
    return fields, pos


def _strip_comments(body: bytes) -> bytes:
    return b"\n".join(line.split(b"#", 1)[0] for line in body.splitlines())


def _check_size(path: Path, width: int, height: int) -> None:
    if width * height > MAX_CELLS:
        raise MapFileError(f"{path}: image of {width} x {height} pixels, more than the "
                           f"{MAX_CELLS} cells a map can have")


def _read_image(path: Path, yaml_path: Path) -> tuple[np.ndarray, int, np.ndarray | None]:
    """PGM through :func:`read_pgm`; PNG and the other formats map_server accepts through
    Pillow, read as map_server reads them: the mean of the colour channels, scaled by the
    image's depth (8 or 16 bits); alpha marks see-through pixels, which only ``scale`` mode
    uses (see ``_channel_mean``)."""
    try:
        check_regular_file(path, "image file")
        with open(path, "rb") as f:
            magic = f.read(2)
    except FileNotFoundError:
        raise MapFileError(f"{yaml_path}: image file {path} not found") from None
    except FileInputError as e:
        raise MapFileError(str(e)) from None
    except OSError as e:
        raise MapFileError(f"{path}: cannot read image ({e})") from None
    if path.suffix.lower() in (".pgm", ".pnm") or magic in (b"P2", b"P5"):
        return (*read_pgm(path), None)

    from PIL import Image, UnidentifiedImageError  # only maps that are not PGM need Pillow

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(path) as im:
                _check_size(path, *im.size)    # from the header, before any pixel is read
                return _channel_mean(im)
    except (Image.DecompressionBombWarning, Image.DecompressionBombError) as e:
        raise MapFileError(f"{path}: the image's header claims more pixels than the "
                           f"{MAX_CELLS} cells a map can have ({_one_line(e)})") from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, EOFError) as e:
        raise MapFileError(f"{path}: cannot read image ({_one_line(e)})") from None


def _channel_mean(im) -> tuple[np.ndarray, int, np.ndarray | None]:
    """(pixels, maxval, opaque): the mean of an image's colour channels, as ROS 2's map_server
    takes it, alpha left out and reported (``opaque``, None without alpha); 16-bit
    greyscale keeps its depth. (ROS 1's map_server averages alpha into trinary maps, which
    reads an opaque RGBA image's unknown grey as free; that is not followed.)"""
    mode = im.mode
    if mode in ("P", "PA"):                 # a palette: its colours (and transparency)
        im = im.convert("RGBA" if "transparency" in im.info or mode == "PA" else "RGB")
    elif mode in ("1", "CMYK", "YCbCr", "LAB", "HSV"):
        im = im.convert("L" if mode == "1" else "RGB")
    mode, a = im.mode, np.asarray(im)
    if mode.startswith("I;16") or (mode == "I" and a.max(initial=0) > 255):
        return np.asarray(a, np.uint16), 65535, None
    if mode in ("I", "F"):
        if a.min(initial=0) < 0 or a.max(initial=0) > 255:
            raise ValueError(f"{mode} image with values outside 0..255")
        return np.rint(a).astype(np.uint16), 255, None
    if a.ndim == 2:
        return a.astype(np.uint16), 255, None
    has_alpha = mode in ("RGBA", "LA", "RGBa", "La")
    colour = a[..., :-1] if has_alpha else a
    mean = np.rint(colour.astype(np.float64).mean(axis=2)).astype(np.uint16)
    return mean, 255, (a[..., -1] == 255) if has_alpha else None


def _pixels_to_values(pixels: np.ndarray, maxval: int, meta: MapMetadata) -> np.ndarray:
    """map_server's pixel -> cell rule for every pixel at once."""
    lightness = pixels.astype(np.float64) / maxval
    if meta.negate:
        lightness = 1.0 - lightness
    if meta.mode == "raw":
        v = np.rint(lightness * 255.0)
        return np.where(v <= OCCUPIED, v, UNKNOWN).astype(np.int8)
    occ = 1.0 - lightness
    values = np.full(pixels.shape, UNKNOWN, np.int8)
    if meta.mode == "scale" and meta.occupied_thresh > meta.free_thresh:
        ratio = (occ - meta.free_thresh) / (meta.occupied_thresh - meta.free_thresh)
        values = np.clip(99.0 * ratio, 1, 99).astype(np.int8)
    values[occ > meta.occupied_thresh] = OCCUPIED
    values[occ < meta.free_thresh] = FREE
    return values


# --- writing -----------------------------------------------------------------------------------

def save_map(grid: OccupancyGrid, path) -> tuple[Path, Path]:
    """Save ``grid`` as ``path`` (YAML) and a trinary P5 image beside it with the same stem.

    Cells 0..25 are written free, 65..100 occupied, the rest unknown (map_saver's rule, which is
    exact for trinary grids). Each file is written to a temporary file and renamed into place,
    the image first, so a reader never sees a half-written map. Returns (yaml path, image path).
    """
    if not isinstance(grid, OccupancyGrid):
        raise MapFileError(f"{path}: save_map needs an OccupancyGrid, got {type(grid).__name__}")
    path = Path(path)
    image_path = path.with_suffix(".pgm")
    if image_path == path:
        raise MapFileError(f"{path}: the YAML file needs a name that does not end in .pgm")
    header = f"P5\n# map resolution {grid.resolution:.6g} m/cell\n{grid.width} {grid.height}\n255\n"
    _write_atomically(image_path, header.encode("ascii") + trinary_image(grid).tobytes())
    meta = {
        "image": image_path.name,
        "mode": "trinary",
        "resolution": float(grid.resolution),
        # repr round-trips a float exactly, so a saved map loads in the same frame.
        "origin": [float(grid.origin[0]), float(grid.origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": SAVE_OCCUPIED_THRESH,
        "free_thresh": SAVE_FREE_THRESH,
    }
    _write_atomically(path, yaml.safe_dump(meta, sort_keys=False, default_flow_style=None).encode())
    return path, image_path


def trinary_image(grid: OccupancyGrid) -> np.ndarray:
    """The map as map_saver draws it: (H, W) uint8, image row 0 the top (the highest y), free
    ``PIXEL_FREE``, occupied ``PIXEL_OCCUPIED``, unknown ``PIXEL_UNKNOWN``. Cells 0..25 count
    as free and 65..100 as occupied (map_saver's rule, exact for trinary grids)."""
    d = grid.data
    pixels = np.full(d.shape, PIXEL_UNKNOWN, np.uint8)
    pixels[(d >= 0) & (d <= 25)] = PIXEL_FREE
    pixels[d >= 65] = PIXEL_OCCUPIED
    return np.ascontiguousarray(pixels[::-1])


def _write_atomically(path: Path, content: bytes) -> None:
    try:
        write_atomically(path, content)
    except OSError as e:
        raise MapFileError(f"{path}: cannot write ({e})") from None


# --- helpers -----------------------------------------------------------------------------------

def _number(path: Path, key: str, value) -> float:
    if isinstance(value, str):
        # YAML 1.1 reads 1e-3 (no dot) as text; map_server's YAML reader takes it as a number
        try:
            value = float(value)
        except ValueError:
            pass
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise MapFileError(f"{path}: key '{key}' must be a finite number, got {value!r}")
    return float(value)


def _one_line(e: Exception) -> str:
    return " ".join(str(e).split())
