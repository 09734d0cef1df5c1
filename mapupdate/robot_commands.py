"""The commands of the robot software: ``update``, ``map``, ``inject``, ``score``, ``compare``
and ``ros1``. They need none of the optional extras."""

from __future__ import annotations

from evaluation import case_folder, edited_world
from gridmap import load_map
from gridmap.metrics import compare_maps
from robot import logmap, replay
from robot.outputs import check_outputs, map_files, map_inputs
from robot.replay import LogSource, Outputs, Placement
from robot.robot_config import load_robot_config
from robot.ros1.node import run_node
from robotlogs import log_observations

from . import summaries


def compare(args) -> int:
    a, b = load_map(args.a), load_map(args.b)
    m = compare_maps(a, b)
    print(f"{'metric':<8}{'value':>10}")
    print(f"{'CC':<8}{m['cc']:>9.2f}%")
    print(f"{'MS':<8}{m['ms']:>9.2f}%")
    print(f"{'OPDF':<8}{m['opdf']:>9.2f}%")
    return 0


def update(args) -> int:
    # the method and --state, then the configuration, are refused before anything is read
    replay.check_update_arguments(args.poses, args.smooth_poses, args.method, args.state)
    config = load_robot_config(args.config)
    check_outputs({"--map": map_inputs(args.map), "--log": [args.log],
                   "--config": [args.config] if args.config else [],
                   "--state": [args.state] if args.state and args.state.exists() else []},
                  {"--out": map_files(args.out), "--state": [args.state] if args.state else [],
                   "--trajectory": [args.trajectory] if args.trajectory else []},
                  both=("--state",))
    start = None if args.initial_pose is None else replay.parse_pose(args.initial_pose)
    log = LogSource(args.log, format=args.format, strict=args.strict,
                    scan_topics=tuple(args.scan_topic) or None, odom_topic=args.odom_topic,
                    pose_topic=args.pose_topic)
    placement = Placement(source=args.poses, initial_pose=start,
                          smooth_window=args.smooth_poses, pose_check=args.pose_check,
                          localizer_config=config.localizer, pose_check_config=config.pose_check)
    outputs = Outputs(args.out, state=args.state, trajectory=args.trajectory)
    summary = replay.update_from_log(args.map, log, outputs, placement, method=args.method,
                                     updater_config=config.updater,
                                     progress=not args.no_progress)
    summary.setdefault("out", str(args.out))
    print("\n".join(summaries.update_lines(summary)))
    return 0


def map_command(args) -> int:
    check_outputs({"--log": [args.log]}, {"--out": map_files(args.out)})
    summary = logmap.map_from_log(args.log, args.out, resolution=args.resolution,
                                  pose_source=args.poses, log_format=args.format,
                                  strict=args.strict, scan_topics=args.scan_topic or None,
                                  odom_topic=args.odom_topic, pose_topic=args.pose_topic,
                                  progress=not args.no_progress)
    print("\n".join(summaries.map_lines(summary)))
    return 0


def inject(args) -> int:
    case_folder.check_case_dir(args.out, args.map, args.log)      # before anything is read
    grid = load_map(args.map)
    found = log_observations(args.log, log_format=args.format, strict=args.strict,
                             scan_topics=args.scan_topic or None, odom_topic=args.odom_topic,
                             pose_topic=args.pose_topic)
    case = edited_world.make_case(grid, found.observations, args.seed, removed=args.removed,
                                  added=args.added, moved=args.moved, people=args.people,
                                  min_views=args.min_views, progress=not args.no_progress)
    case_folder.write_case(case, args.out, map_path=args.map, log_path=args.log)
    print("\n".join(case_folder.case_lines(case, args.out)))
    return 0


def score(args) -> int:
    if args.json is not None:
        check_outputs({"DIR": [args.case / f for f in case_folder.CASE_FILES],
                       "OUT.yaml": map_inputs(args.updated)}, {"--json": [args.json]})
    scores = case_folder.score_case(args.case, load_map(args.updated))
    print("\n".join(case_folder.score_lines(scores)))
    if args.json is not None:
        case_folder.write_scores(scores, args.json)
        print(f"wrote {args.json}")
    return 0


def ros1(args) -> int:
    # an empty --config (a launch file's unset argument) means none
    return run_node(args.map, args.config or None, args.ros_argv)


def ros2(args) -> int:
    from robot.ros2.node import run_node as run_ros2_node    # rclpy: the [ros2] extra

    return run_ros2_node(args.map, args.config or None, args.autostart, args.ros_argv)
