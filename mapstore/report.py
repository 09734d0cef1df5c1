"""The store's answers in words: ``mapupdate store log``, ``show`` and ``diff``."""

from __future__ import annotations

import textwrap
import time

from gridmap import FREE, OCCUPIED, UNKNOWN

from .cells import CellChanges
from .merge import RULE_TEXT, Conflicts
from .store import Version

KINDS = ("occupied_to_free", "free_to_occupied", "unknown_to_free", "unknown_to_occupied",
         "known_to_unknown")


def when(seconds: float | None) -> str:
    if seconds is None:
        return "-"
    return time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime(seconds))


def made_by(v: Version) -> str:
    """A few words on what made a version."""
    m = v.meta
    if v.merge_parent is not None:
        n = m.get("cells", {}).get("conflicts", 0)
        return (f"merge of v{v.merge_parent} into v{v.parent} (base "
                f"{'v' + str(m['base']) if m.get('base') else 'none'}; {n} conflict"
                f"{'s' * (n != 1)}" + (f" to {m.get('conflicts_to')}" if n else "") + ")")
    if m.get("method") == "rollback":
        return f"rollback to v{m.get('rollback_of')}"
    if m.get("method") == "import":
        return f"import of {m.get('source', '?')}"
    parts = [m.get("robot"), m.get("log_name") or m.get("log"), m.get("method")]
    return " ".join(str(p) for p in parts if p) or "-"


def parents(v: Version) -> str:
    if v.parent is None:
        return "-"
    return f"v{v.parent}" + (f"+v{v.merge_parent}" if v.merge_parent is not None else "")


def log_lines(versions: list[Version], store_name: str, require_approval: bool) -> list[str]:
    rule = "review on: new versions wait for approval" if require_approval else "review off"
    out = [f"{store_name}: {len(versions)} version{'s' * (len(versions) != 1)} ({rule})"]
    if not versions:
        return out
    out.append(f"{'ver':>5}  {'status':<9}{'parent':>9}  {'committed (UTC)':<20}"
               f"{'changed':>9}{'freed':>8}{'drawn':>8}  made by")
    for v in versions:
        c = v.counts or {}
        tags = f"  [{', '.join(v.tags)}]" if v.tags else ""
        out.append(f"{'v' + str(v.number):>5}  {v.status:<9}"
                   f"{parents(v):>9}  {when(v.created):<20}"
                   f"{c.get('cells_changed', '-'):>9}{c.get('cells_freed', '-'):>8}"
                   f"{c.get('cells_drawn', '-'):>8}"
                   f"  {made_by(v)}{tags}")
    return out


def show_lines(v: Version) -> list[str]:
    h, w = v.shape
    out = [f"v{v.number}: {v.status}" + (f" {when(v.reviewed)}" if v.reviewed else "")
           + (f" ({v.note})" if v.note else ""),
           f"  {'parent':<16} {parents(v) if v.parent else '- (a first map)'}",
           f"  {'committed':<16} {when(v.created)} UTC",
           f"  {'map':<16} {w} x {h} cells at {v.resolution:g} m, origin "
           f"({v.origin[0]:g}, {v.origin[1]:g})"]
    if v.tags:
        out.append(f"  {'tags':<16} {', '.join(v.tags)}")
    if v.counts:
        out.append(f"  {'changes':<16} {v.counts['cells_changed']} cells against v{v.parent}: "
                   + ", ".join(f"{v.counts[k]} {k.replace('_', ' ')}" for k in KINDS
                               if v.counts.get(k)))
    for key, value in sorted(_flat(v.meta).items()):
        out += textwrap.wrap(f"{key:<16} {value}", 96, initial_indent="  ",
                             subsequent_indent=" " * 19, break_on_hyphens=False)
    return out


def conflict_lines(conflicts: Conflicts, shape: tuple[int, int], limit: int = 20) -> list[str]:
    """A merge's conflicts, cell by cell (the first ``limit``): where, and each side's value."""
    n = len(conflicts)
    out = [f"  {'conflicts':<16} {n} cell{'s' * (n != 1)} changed in different ways on the two "
           f"sides ({RULE_TEXT})"]
    if not n:
        return out
    out.append(f"    {'row':>6} {'col':>6} {'base':>6} {'ours':>6} {'theirs':>7} {'chosen':>7}")
    rows, cols = conflicts.index // shape[1], conflicts.index % shape[1]
    for k in range(min(n, limit)):
        out.append(f"    {rows[k]:>6} {cols[k]:>6} {_value(conflicts.base[k]):>6} "
                   f"{_value(conflicts.ours[k]):>6} {_value(conflicts.theirs[k]):>7} "
                   f"{_value(conflicts.chosen[k]):>7}")
    if n > limit:
        out.append(f"    ... {n - limit} more")
    return out


def _value(v) -> str:
    return {FREE: "free", OCCUPIED: "occ", UNKNOWN: "unk"}.get(int(v), "-")


def _flat(meta: dict, prefix: str = "") -> dict:
    """Nested sections as ``section.key``; a section of plain values stays one line."""
    out = {}
    for key, value in meta.items():
        if isinstance(value, dict) and any(isinstance(x, dict) for x in value.values()):
            out.update(_flat(value, f"{prefix}{key}."))
        elif isinstance(value, dict):
            out[prefix + key] = ", ".join(f"{k}={value[k]}" for k in sorted(value))
        else:
            out[prefix + key] = value
    return out


def diff_lines(a: int, b: int, changes: CellChanges, shape: tuple[int, int]) -> list[str]:
    c = changes.counts()
    out = [f"v{a} -> v{b}: {c['cells_changed']} cells changed ({c['cells_freed']} freed, "
           f"{c['cells_drawn']} drawn)"]
    out += [f"  {k:<22}{c[k]:>10}" for k in KINDS]
    if len(changes):
        rows, cols = changes.index // shape[1], changes.index % shape[1]
        out.append(f"  within rows {rows.min()}-{rows.max()}, columns {cols.min()}-{cols.max()}")
    return out
