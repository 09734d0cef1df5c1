"""Output paths checked before any work: a command never writes over one of its inputs, and
no two of its outputs are the same file. Paths are compared after resolving links and ``..``
(and by inode for files that exist, which catches hard links), and a map's YAML brings its
image along (``--out m.yml`` writes ``m.pgm``, which may be the input map's image)."""

from __future__ import annotations

import os
from pathlib import Path

from gridmap import MapUpdatingError
from gridmap.map_io import read_map_yaml


class OutputClash(MapUpdatingError, ValueError):
    """An output path that names an input or another output."""


def map_files(yaml_path) -> list[Path]:
    """The files ``gridmap.save_map(grid, yaml_path)`` writes: the YAML and its image."""
    p = Path(yaml_path)
    return [p, p.with_suffix(".pgm")]


def map_inputs(yaml_path) -> list[Path]:
    """The files a map_server map is read from: its YAML and the image it names (when the
    YAML can be read; otherwise loading it will say what is wrong)."""
    try:
        return [Path(yaml_path), read_map_yaml(yaml_path).image]
    except (MapUpdatingError, OSError):
        return [Path(yaml_path)]


def check_outputs(inputs: dict[str, list], outputs: dict[str, list],
                  both: tuple[str, ...] = ()) -> None:
    """Refuse, naming both, an output file that is an input file or another output. ``inputs``
    and ``outputs`` map an option's name (``--map``) to its files; the options in ``both``
    are read and then written on purpose (``--state``) and may name themselves."""
    seen: dict[object, str] = {}
    for name, files in inputs.items():
        for f in files:
            for key in _keys(f):
                seen.setdefault(key, f"input {name} ({f})")
    written: dict[object, str] = {}
    for name, files in outputs.items():
        for f in files:
            if Path(f).is_dir():
                raise OutputClash(f"{f}: {name} names a folder, not a file")
            for key in _keys(f):
                other = written.get(key) or seen.get(key)
                if other and not (name in both and other.split(" ", 2)[1] == name):
                    raise OutputClash(f"{name} would write {f}, which is {other}: choose "
                                      "another path")
                written.setdefault(key, f"output {name} ({f})")


def _keys(path) -> list:
    """What identifies a file: its resolved path, and its inode when it exists."""
    p = Path(path)
    keys: list = [str(p.resolve())]
    try:
        st = os.stat(p)
        keys.append((st.st_dev, st.st_ino))
    except OSError:
        pass
    return keys
