"""The summaries of ``mapupdate update`` and ``mapupdate map`` as lines for people: the library
returns what happened as a dict (``onboard.replay.update_from_log``, ``onboard.logmap.map_from_log``),
and the command line says it."""

from __future__ import annotations

from onboard.replay import CHANGE_KEYS


def update_lines(s: dict) -> list[str]:
    """The summary of ``update_from_log`` as lines for the command line: the map written and
    its cells changed by kind, the scans and what became of them, what the readers skipped
    (one line per kind), the gate's refusals by rule, the evidence of change left below the
    threshold, how the localiser fared, warnings. When no cell changed, a line says why."""
    g = s.get
    changed = sum(g(k, 0) for k in CHANGE_KEYS)
    used = f"method {g('method', 'paper')}, poses {g('pose_source')}" + (
        f", profile {g('profile')}" if g("profile") else "")
    out = [f"wrote {g('out')}: {_changes_text(s) if changed else '0 cells changed'}; {used}"]
    if g("state_loaded") == "next session":
        out.append(f"  a new session from the state {g('state')} (what it carries from "
                   "session to session; its buffers start afresh on this map)")
    if g("differences"):
        out.append(f"  configuration over the {g('profile')} profile: "
                   + "; ".join(g("differences")))
    skipped = sum((g("read") or {}).get("skipped", {}).values())
    out.append(f"  {g('scans', 0)} scans read" + (f" ({skipped} lines or messages of the log "
                                                   "skipped, below)" if skipped else "")
               + f", {g('scans_used', g('scans', 0))} used; {g('scans_processed', 0)} "
               f"processed past the gate, {g('scans_dropped_as_lost', 0)} dropped as lost, "
               f"{g('scans_refused_by_pose_check', 0)} refused by the pose check"
               + (f", {g('scans_corrected_by_pose_check')} placed by it at a pose that fits "
                  f"better" if g("scans_corrected_by_pose_check") else "")
               + (f", {g('scans_off_map')} off the map" if g("scans_off_map") else ""))
    out += [f"  {line}" for line in g("read_lines") or []]
    if not changed:
        out.append(f"  0 cells changed: {_why_unchanged(s)}")
    else:
        out += [f"  {part}" for part in (_gate_text(s), _pending_text(s)) if part]
    smooth = g("smoothing") or {}
    if smooth.get("scans_smoothed"):
        out.append(f"  {smooth['scans_smoothed']} recorded poses jittered against the odometry "
                   f"and were smoothed over {smooth['window_s']:g} s (--smooth-poses 0: as "
                   f"recorded)" + (f"; {smooth['restarts']} jumps of the localisation restarted "
                                   f"the smoothing" if smooth.get("restarts") else ""))
    out += [f"  warning: {w}" for w in _warnings(s)]
    track = g("tracking")
    if track:
        out.append(f"  localiser: {track['start']}")
        out += [f"  localiser {e['state']} {e['after']:.1f} s into the log: {e['reason']}"
                for e in track["events"]]
        if g("scans_not_tracking"):
            out.append(f"  warning: {g('scans_not_tracking')} scans were not used: the "
                       "localiser was not tracking")
    if g("trajectory"):
        out.append(f"  wrote {g('trajectory')} (TUM)")
    return out


def _changes_text(s: dict) -> str:
    """"12 occupied cells freed, 40 free cells occupied, 8795 unknown cells now known (8790
    free, 5 occupied)"."""
    g = s.get
    known = g("unknown_to_free", 0) + g("unknown_to_occupied", 0)
    text = (f"{g('occupied_to_free', 0)} occupied cells freed, {g('free_to_occupied', 0)} free "
            f"cells occupied, {known} unknown cells now known ({g('unknown_to_free', 0)} free, "
            f"{g('unknown_to_occupied', 0)} occupied)")
    if g("known_to_unknown"):
        text += f", {g('known_to_unknown')} known cells now unknown"
    return text


def _gate_text(s: dict, brief: bool = False) -> str:
    """"the gate refused 380 of 406 scans: fast turn 300, no motion 80" ("" when it refused
    none); ``brief``: the rules in parentheses."""
    gated = s.get("scans_gated", 0)
    if not gated:
        return ""
    rules = sorted((s.get("gated_by") or {}).items(), key=lambda kv: (-kv[1], kv[0]))
    listed = ", ".join(f"{rule} {n}" for rule, n in rules)
    head = f"the gate refused {gated} of {s.get('scans_used', gated)} scans"
    text = f"{head} ({listed})" if brief else f"{head}: {listed}"
    if s.get("scans_confirming"):
        text += (f"; {s['scans_confirming']} of them, views already taken, confirmed the "
                 "map's surfaces")
    return text


def _pending_text(s: dict, brief: bool = False) -> str:
    """The cells whose evidence of change stayed below the threshold ("" for none, or for a
    method that keeps no such evidence)."""
    e = s.get("evidence")
    if not e or not e.get("pending_cells"):
        return ""
    head = f"{e['pending_cells']} cells collected evidence of change below the threshold"
    if e.get("pending_few_observations") is None:      # the updater did not count flags
        return head
    few = f"{e['pending_few_observations']} seen by fewer than {e['threshold']} processed scans"
    if brief:
        return f"{head} ({few})"
    return f"{head}: {few}, {e['pending_outvoted']} outvoted by scans that saw them unchanged"


def _why_unchanged(s: dict) -> str:
    """Why the output changed no cell: the evidence left below the threshold and the scans
    that never reached the map, each counted."""
    g = s.get
    why = [part for part in (_pending_text(s, brief=True), _gate_text(s, brief=True)) if part]
    for key, text in (("scans_refused_by_pose_check", "the pose check refused {} scans"),
                      ("scans_dropped_as_lost", "the lost check dropped {} scans"),
                      ("scans_off_map", "{} scans lay off the map"),
                      ("scans_not_tracking", "{} scans came while the localiser was not "
                                             "tracking")):
        if g(key):
            why.append(text.format(g(key)))
    processed = g("scans_processed", 0)
    if not processed:
        why.insert(0, "no scan was processed")
    elif not why:
        why.append(f"the {processed} scans processed found no evidence of change"
                   if g("evidence") is not None else
                   f"the {processed} scans processed gave no cell evidence enough to change it")
    return "; ".join(why)


def _warnings(s: dict) -> list[str]:
    """What a user should look at: scans whose poses disagree with the map, mostly, and stamps
    that do not tell time."""
    g = s.get
    asked = g("scans_processed", 0) + g("scans_refused_by_pose_check", 0)
    stamps = _stamps_text(g("timestamps"))
    out = [stamps] if stamps else []
    if asked and g("scans_refused_by_pose_check", 0) > 0.5 * asked:
        out.append(f"the pose check refused {g('scans_refused_by_pose_check')} of the {asked} "
                   "scans past the gate: their poses disagree with the map (drifted odometry? "
                   "try --poses localizer)")
    if g("format") in ("ros1", "ros2") and (g("timestamps") or {}).get("earlier_than_before"):
        out.append("the bag's clock went back: tf and odometry are looked up at the scans' "
                   "stamps, which now stand for two moments of the recording, so scans may be "
                   "placed at poses of the other; check the trajectory (--trajectory)")
    if g("scans_processed", 0) and g("scans_dropped_as_lost", 0) > 0.5 * g("scans_processed"):
        out.append(f"the lost check dropped {g('scans_dropped_as_lost')} of the "
                   f"{g('scans_processed')} scans processed: most beams disagree with the map "
                   "there (wrong poses, or a place the map does not cover)")
    return out


def _stamps_text(t: dict | None) -> str:
    """"404 of 406 scans have the same timestamp as the scan before; ...", or "" when every
    stamp increased."""
    if not t or not (t["same_as_before"] or t["earlier_than_before"]):
        return ""
    same, earlier, n = t["same_as_before"], t["earlier_than_before"], t["scans"]
    if same and earlier:
        what = f"{same} of {n} scans have the same timestamp as the scan before and {earlier} " \
               "an earlier one"
    elif same:
        what = f"{same} of {n} scans have the same timestamp as the scan before"
    else:
        what = f"{earlier} of {n} scans have an earlier timestamp than the scan before"
    period = "the median interval between the log's scans" if t["period_measured"] else \
        "the log gives no interval between its scans"
    return f"{what}; their times were taken from scan order, {t['period_s']:g} s after the " \
           f"scan before ({period}), for the gate and the pose smoothing"


def map_lines(s: dict) -> list[str]:
    """The summary of ``map_from_log`` as lines for the command line."""
    w, h = s["size"]
    out = [f"wrote {s['out']}: {w} x {h} cells at {s['resolution']} m, origin "
           f"({s['origin'][0]:g}, {s['origin'][1]:g}); {s['occupied']} occupied, "
           f"{s['free']} free",
           f"  {s['scans_mapped']} of {s['scans']} scans mapped (poses: {s['pose_source']})"]
    return out + [f"  {line}" for line in s["read_lines"]]
