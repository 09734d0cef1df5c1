"""The figures a benchmark script hands ``run.py`` (``--json PATH``), so that ``run.py
--baseline REV`` can set a revision's beside the working tree's.

A script adds its figures by name (a time, a size: a number and its unit) and the digests of
its outputs (an output map, the particles after the last update, a table of counts): two
runs gave the same output when its digests are equal. The file is one JSON document:
``{"figures": {name: {"value": v, "unit": u}}, "outputs": {name: sha256}}``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
from pathlib import Path

import numpy as np


class Figures:
    def __init__(self):
        self.figures: dict[str, dict] = {}
        self.outputs: dict[str, str] = {}

    def add(self, name: str, value: float, unit: str = "") -> None:
        self.figures[name] = {"value": float(value), "unit": unit}

    def output(self, name: str, *parts) -> None:
        """The digest of ``parts``: arrays by dtype, shape and bytes, anything else by its
        ``repr`` (floats, and dataclasses of them, to the bit)."""
        h = hashlib.sha256()
        for part in parts:
            if isinstance(part, np.ndarray):
                a = np.ascontiguousarray(part)
                h.update(f"{a.dtype.str}{a.shape}".encode())
                h.update(a.data)
            else:
                h.update(repr(part).encode())
        self.outputs[name] = h.hexdigest()

    def write(self, path: str | Path | None) -> None:
        if path:
            Path(path).write_text(json.dumps({"figures": self.figures,
                                              "outputs": self.outputs}, indent=1))


def add_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", metavar="PATH",
                        help="also write the figures and output digests there (run.py)")
