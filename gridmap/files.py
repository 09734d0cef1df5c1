"""Reading a user's small text files without being taken in: a path that is a device or a
link to one (an endless ``/dev/zero``), a file far larger than its kind ever is, bytes that
are not text, and YAML whose aliases expand a kilobyte into gigabytes ("billion laughs") are
refused with one line, before anything big is allocated.

Every YAML file of the project (maps, scenarios, configurations) is read through
``load_yaml``; image files are checked with ``check_regular_file`` before they are opened.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

import yaml

from .errors import MapUpdatingError

MAX_TEXT_BYTES = 16 * 1024 * 1024     # a map YAML, a scenario or a config is a few KB
MAX_YAML_NODES = 1_000_000            # nodes after expanding aliases


class FileInputError(MapUpdatingError, ValueError):
    """A file that is not what its kind can be; the message names the file."""


def check_regular_file(path, what: str, limit: int | None = None) -> int:
    """The size of ``path`` [bytes] after making sure it is a regular file (links followed)
    of at most ``limit`` bytes. Raises ``FileNotFoundError`` when it is missing, else
    ``FileInputError``."""
    path = Path(path)
    try:
        st = os.stat(path)
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {what} not found") from None
    except OSError as e:
        raise FileInputError(f"{path}: cannot read the {what} ({e.strerror or e})") from None
    if not stat.S_ISREG(st.st_mode):
        kind = "a folder" if stat.S_ISDIR(st.st_mode) else "a FIFO (a named pipe)" \
            if stat.S_ISFIFO(st.st_mode) else "not a regular file (a device?)"
        raise FileInputError(f"{path}: the {what} is {kind}")
    if limit is not None and st.st_size > limit:
        raise FileInputError(f"{path}: the {what} is {st.st_size} bytes, more than the "
                             f"{limit} a {what} can be")
    return st.st_size


def read_text(path, what: str, limit: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of a small file (see the module docstring)."""
    path = Path(path)
    check_regular_file(path, what, limit)
    try:
        with open(path, "rb") as f:
            raw = f.read(limit + 1)          # the file may have grown since the check
    except OSError as e:
        raise FileInputError(f"{path}: cannot read the {what} ({e.strerror or e})") from None
    if len(raw) > limit:
        raise FileInputError(f"{path}: the {what} is more than {limit} bytes")
    if b"\x00" in raw:
        raise FileInputError(f"{path}: the {what} is a binary file, not text")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        raise FileInputError(f"{path}: the {what} is not UTF-8 text (byte {e.start})") from None


def load_yaml(path, what: str, error: type[Exception] = FileInputError):
    """The YAML document of a small file; ``error`` for a document that is not valid YAML or
    that expands past ``MAX_YAML_NODES`` nodes through its aliases."""
    return parse_yaml(read_text(path, what), f"{path}", error)


def parse_yaml(text: str, source: str, error: type[Exception] = FileInputError):
    """``yaml.safe_load`` with the alias bomb refused (see ``load_yaml``)."""
    loader = None
    try:
        loader = yaml.SafeLoader(text)      # refuses control characters already
        node = loader.get_single_node()
        if node is None:
            return None
        size = _expanded_size(node)
        if size > MAX_YAML_NODES:
            raise error(f"{source}: the YAML expands to more than {MAX_YAML_NODES} nodes "
                        "through its aliases (refused)")
        return loader.construct_document(node)
    except yaml.YAMLError as e:
        raise error(f"{source}: not valid YAML ({' '.join(str(e).split())})") from None
    except RecursionError:
        raise error(f"{source}: the YAML nests too deeply") from None
    finally:
        if loader is not None:
            loader.dispose()


def _expanded_size(root) -> int:
    """Nodes of the document with every alias expanded, counted on the composed graph (each
    node once, its expanded size remembered), so the count itself costs nothing. A node that
    contains itself (``&a [*a]``) expands without end."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()
    stack = [(root, False)]
    while stack:
        node, children_done = stack.pop()
        kids = _children(node)
        if children_done:
            open_nodes.discard(id(node))
            sizes[id(node)] = min(1 + sum(sizes[id(k)] for k in kids), MAX_YAML_NODES + 1)
            continue
        if id(node) in sizes:
            continue
        open_nodes.add(id(node))
        stack.append((node, True))
        for k in kids:
            if id(k) in open_nodes:
                raise yaml.YAMLError("a node that contains itself expands without end")
            if id(k) not in sizes:
                stack.append((k, False))
    return sizes[id(root)]


def _children(node) -> list:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []
