"""The scans a live node holds before it processes them, bounded by count (``queue_size``) and
by memory: past either bound the oldest go, counted, so that a burst of large scans cannot
grow a node's memory without limit."""

from __future__ import annotations

import array
import collections

import numpy as np

QUEUE_BYTES = 128 * 2**20      # [bytes] of waiting scans at most
PY_FLOAT_BYTES = 32            # a Python float in a list or tuple (rospy): object and pointer


def scan_bytes(ranges, intensities=()) -> int:
    """What a waiting scan holds, about: its ranges and intensities as the message keeps them
    (rclpy: arrays of float32; rospy: tuples of Python floats; a record: a NumPy array)."""
    total = 256
    for values in (ranges, intensities):
        if isinstance(values, np.ndarray):
            total += values.nbytes
        elif isinstance(values, array.array):
            total += values.itemsize * len(values)
        else:
            total += PY_FLOAT_BYTES * len(values)
    return total


class ScanQueue:
    """First in, first out; ``push`` drops the oldest past ``max_items`` or ``max_bytes`` and
    says how many it dropped."""

    def __init__(self, max_items: int, max_bytes: int = QUEUE_BYTES):
        self.max_items, self.max_bytes = max_items, max_bytes
        self._items: collections.deque = collections.deque()
        self.bytes = 0

    def push(self, item, size: int) -> int:
        self._items.append((item, size))
        self.bytes += size
        dropped = 0
        while len(self._items) > 1 and (len(self._items) > self.max_items
                                        or self.bytes > self.max_bytes):
            self.bytes -= self._items.popleft()[1]
            dropped += 1
        return dropped

    def first(self):
        return self._items[0][0]

    def pop(self):
        item, size = self._items.popleft()
        self.bytes -= size
        return item

    def __len__(self) -> int:
        return len(self._items)
