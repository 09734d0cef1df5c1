"""A store's versions as a graph: each version's parent and, for a merge, its second parent
(the version merged in). What a merge needs from it: whether one version already holds
another's changes, their common ancestor, and which side saw the world last."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Node:
    parent: int | None
    merge_parent: int | None      # set on a merge: the version merged into ``parent``
    created: float                # [s] since the epoch


Graph = dict[int, Node]


def ancestors(graph: Graph, v: int) -> set[int]:
    """``v`` and every version it descends from, through both parents of a merge."""
    seen, todo = set(), [v]
    while todo:
        n = todo.pop()
        if n in seen or n not in graph:
            continue
        seen.add(n)
        node = graph[n]
        todo += [p for p in (node.parent, node.merge_parent) if p is not None]
    return seen


def holds(graph: Graph, a: int, b: int) -> bool:
    """Whether version ``a`` holds ``b``'s changes: ``b`` is ``a`` or one of its ancestors."""
    return b in ancestors(graph, a)


def common_ancestor(graph: Graph, a: int, b: int) -> int | None:
    """The newest version both descend from (None: two unrelated histories)."""
    common = ancestors(graph, a) & ancestors(graph, b)
    return max(common) if common else None


def newest_session(graph: Graph, tip: int, base: int | None) -> float:
    """[s] when the newest session on ``tip``'s side since ``base`` was committed (a merge is
    not a session: it saw nothing)."""
    since = ancestors(graph, tip) - (ancestors(graph, base) if base is not None else set())
    times = [graph[n].created for n in since if graph[n].merge_parent is None]
    return max(times, default=float("-inf"))
