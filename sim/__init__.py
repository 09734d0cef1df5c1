"""The simulated warehouse: a pymunk world of walls, racks, movable objects and walking people,
a differential-drive robot with drifting odometry and exact 2D lidars, and the ground-truth map
of every session. Imports ``gridmap`` only, never the robot software.

    scenario = load_scenario("scenarios/aws_small_warehouse.yaml")
    world = World(scenario, "W2", seed=7)
    for msg in world.run():          # OdometryMsg and ScanMsg in time order
        ...
    truth = world.ground_truth()     # G in grid_frame(scenario)

or, to drive the robot by command instead of along its route:

    world = World(scenario, "W2", seed=7)
    msgs = world.step(0.4, 0.1)      # hold v [m/s], w [rad/s] for a physics step

or several robots, each a moving obstacle in the others' scans (``sim.fleet``):

    fleet = FleetWorld(scenario, "W2", [FleetMember(start, route), ...], seed=7)
    for robot, msg in fleet.run():   # each robot's messages, all in time order
        ...
"""

from .groundtruth import grid_frame
from .drawing import render_world
from .scenario import (Change, LidarSpec, Obstacle, PersonSpec, RobotSpec, Scenario,
                       ScenarioError, SessionSpec, WorldSpec, load_scenario, quick_variant,
                       scenario_from_dict)
from .world import OdometryMsg, ScanMsg, World
from .fleet import FleetMember, FleetWorld

__all__ = ["Change", "FleetMember", "FleetWorld", "LidarSpec", "Obstacle", "OdometryMsg",
           "PersonSpec", "RobotSpec", "ScanMsg", "Scenario", "ScenarioError", "SessionSpec", "World", "WorldSpec",
           "grid_frame", "load_scenario", "quick_variant", "render_world", "scenario_from_dict"]
