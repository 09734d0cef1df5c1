"""Scans that never reached the node, told by their publishers' counters: ROS 1's
``header.seq`` and ROS 2's publication sequence number rise by one with each message a
publisher sends, so a jump is that many messages lost on the way (in the middleware's queue,
on the network). Counted per source (ROS 1: the publishing node; ROS 2, whose message info
does not name the publisher: the topic and the scan's frame, one lidar each); a counter that
goes back is a publisher started again, not a loss. Messages lost after the last one that
arrived cannot be seen."""

from __future__ import annotations

# what rmw reports when the middleware does not number its messages
UNSUPPORTED = (0, 2**64 - 1)


class Gaps:
    def __init__(self):
        self._last: dict = {}
        self.lost = 0
        self.numbered = False               # whether any message came numbered

    def see(self, source, number) -> int:
        """Note message ``number`` from ``source``; how many before it never arrived."""
        if number is None or number in UNSUPPORTED:
            return 0
        self.numbered = True
        last = self._last.get(source)
        self._last[source] = number
        if last is None or number <= last:
            return 0
        self.lost += number - last - 1
        return number - last - 1
