"""What the ROS 2 node offers and sends: its services (``~/save``, ``~/commit``, ``~/reset``,
``std_srvs/Trigger``, answered only while the node is active; ``~/save_map``, Nav2's
``nav2_msgs/SaveMap`` with a path, where that package is installed), the map, its metadata and
the costmap's updates, the map store's link, and the resumption of a map and buffers the node
saved before. Functions over the node, kept apart from its lifecycle and its scans."""

from __future__ import annotations

from pathlib import Path

from gridmap import MapUpdatingError, OccupancyGrid, save_map
from updater import MapUpdater

from ..ros_common.grids import changed_box, message_fields
from ..ros_common.settings import check_save_path, refuse_saving_over_the_map
from ..ros_common.store_link import StoreLink
from std_srvs.srv import Trigger

try:                 # built from its definition by `make ros2` (no wheel carries it)
    from map_msgs.msg import OccupancyGridUpdate
except ImportError:
    OccupancyGridUpdate = None
try:                 # Nav2's, where Nav2 is installed (or `make ros2` built its SaveMap)
    from nav2_msgs.srv import SaveMap
except ImportError:
    SaveMap = None


def state_path(save_path: str) -> Path:
    """Where the updater's buffers are saved beside the map: ``map.yaml`` -> ``map.state.npz``."""
    return Path(save_path).with_suffix(".state.npz")


def check_paths(save_path: str, map_path) -> None:
    check_save_path(save_path)
    refuse_saving_over_the_map(save_path, map_path)


def store_link(s) -> StoreLink | None:
    return StoreLink(s.store, s.robot_name, s.store_poll_period) if s.store else None


def resume(node, reference: OccupancyGrid):
    """(the updater, why ``save`` refuses, how): the paper's updater saved at ``save_path``'s
    state file when it was made on this reference map with this configuration ("resumed");
    the session after it, buffers afresh and the faces rule's counts carried, when this
    reference map is the map it made ("next session"); otherwise (None, ""), or, when a map
    is already at ``save_path``, a refusal to write over what this node did not make (a
    restart after a crash would lose the updated map)."""
    s = node.settings
    saved, state = Path(s.save_path), state_path(s.save_path)
    if s.method == "paper" and state.exists():
        try:
            updater = MapUpdater.load(state)
        except MapUpdatingError as e:
            return None, f"{state} cannot be resumed ({' '.join(str(e).split())})", ""
        ref = updater.reference_map
        if ref.same_frame(reference) and updater.config == node.updater_config:
            if (ref.data == reference.data).all():
                node.get_logger().info(f"resumed from {state}: the buffers of the map saved at "
                                       f"{saved}")
                return updater, "", "resumed"
            if (updater.updated_map().data == reference.data).all():
                # started on the map that session made: the next session, with what it
                # carries (as ``mapupdate update --state`` does); nothing at save_path is lost
                nxt = MapUpdater(reference, updater.config, faces=updater.carried_faces())
                node.get_logger().info(f"the next session after the one saved at {state}: "
                                       f"{nxt.face_cells()} cells of the faces rule's counts "
                                       "carried")
                return nxt, "", "next session"
        return None, (f"{state} was saved on another reference map or configuration; "
                      f"{saved} is not written over: move them or set another save_path"), ""
    if saved.exists():
        return None, (f"{saved} exists and this node did not make it (no state to resume "
                      f"at {state}); it is not written over: move it or set another "
                      "save_path"), ""
    return None, "", ""


def create(node) -> list:
    out = [node.create_service(Trigger, f"~/{name}", handler)
           for name, handler in (("save", lambda q, r: _trigger(node, r, _save, node)),
                                 ("commit", lambda q, r: _trigger(node, r, _commit, node)),
                                 ("reset", lambda q, r: _trigger(node, r, _reset, node)))]
    if SaveMap is not None:
        out.append(node.create_service(SaveMap, "~/save_map",
                                       lambda q, r: _save_map(node, q, r)))
    return out


def _trigger(node, response, action, *args):
    if node.lifecycle.state != "active":
        ok, said = False, f"the node is not active (state '{node.lifecycle.state}')"
    elif node.pipeline is None:
        ok, said = False, "no reference map yet"
    else:
        ok, said = action(*args)
    response.success, response.message = ok, said
    return response


def _write(node, path: str) -> tuple[bool, str]:
    node._drain(force=True)
    try:
        save_map(node.pipeline.updater.updated_map(), Path(path))
        if isinstance(node.pipeline.updater, MapUpdater):
            node.pipeline.updater.save(state_path(path))
    except (MapUpdatingError, OSError) as e:
        return False, f"cannot save: {' '.join(str(e).split())}"
    return True, f"saved {path}"


def _save(node) -> tuple[bool, str]:
    if node._save_refusal:
        return False, f"cannot save: {node._save_refusal}"
    return _write(node, node.settings.save_path)


def _save_map(node, request, response):
    """Nav2's SaveMap: ``map_url`` a path (``file://`` or none; .yaml added when missing; ""
    for ``save_path``); trinary PGM only, as the node's maps are."""
    url = request.map_url.removeprefix("file://")
    if request.image_format not in ("", "pgm") or request.map_mode not in ("", "trinary"):
        why = "only trinary PGM maps are saved"
    elif node.lifecycle.state != "active" or node.pipeline is None:
        why = f"the node is not active (state '{node.lifecycle.state}')"
    elif not url:
        ok, why = _save(node)
        why = "" if ok else why
    else:
        path = url if url.endswith(".yaml") else url + ".yaml"
        try:
            check_paths(path, node.map_path)
            ok, why = _write(node, path)
            why = "" if ok else why
        except MapUpdatingError as e:
            why = " ".join(str(e).split())
    if why:
        node.get_logger().error(f"save_map: {why}")
    response.result = not why
    return response


def _commit(node) -> tuple[bool, str]:
    node._drain(force=True)
    if node.store is None:
        node._adopt(node.pipeline.updater.updated_map())
        return True, "the updated map is the reference now"
    ok, said, then = node.store.commit_session(node.pipeline, node.settings.method,
                                               node.updater_config)
    if ok:
        node._adopt(then)
    return ok, said


def _reset(node) -> tuple[bool, str]:
    node._adopt(node.pipeline.updater.reference_map, carry=False)
    return True, "buffers and the faces rule's counts cleared; the reference is unchanged"


def take_newer_version(node) -> None:
    """A newer approved version in the store (another robot's, or this one's reviewed)
    becomes the reference, buffers afresh."""
    if node.store is None or node.pipeline is None:
        return
    try:
        updater = node.pipeline.updater
        newer = node.store.newer(session=(updater.reference_map, updater.updated_map()))
    except MapUpdatingError as e:
        return node._skip("map store unusable", e)
    if newer is not None:
        node._adopt(newer[1])
        node.health.counts["store_versions_taken"] += 1
    node.health.counts["store_version"] = node.store.version or 0


def publish_map(node, grid: OccupancyGrid, before) -> None:
    """``map_updated`` and its metadata; the box that changed since ``before`` on
    ``map_updated_updates``."""
    from nav_msgs.msg import OccupancyGrid as GridMsg

    f = message_fields(grid)
    msg = GridMsg()
    msg.header.stamp = node.get_clock().now().to_msg()
    msg.header.frame_id = node.settings.map_frame
    msg.info.map_load_time = msg.header.stamp
    msg.info.resolution = f["resolution"]
    msg.info.width, msg.info.height = f["width"], f["height"]
    msg.info.origin.position.x, msg.info.origin.position.y = f["origin"]
    msg.info.origin.orientation.w = 1.0
    msg.data = f["data"]
    node._outputs["map"].publish(msg)
    node._outputs["metadata"].publish(msg.info)
    box = None if before is None else changed_box(before, grid.data)
    if box is not None and "updates" in node._outputs:
        x, y, w, h = box
        update = OccupancyGridUpdate()
        update.header = msg.header
        update.x, update.y, update.width, update.height = x, y, w, h
        update.data = grid.data[y:y + h, x:x + w].reshape(-1).tolist()
        node._outputs["updates"].publish(update)
