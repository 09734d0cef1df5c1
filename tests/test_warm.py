"""``python -m mapupdate.warm`` (run by ``make setup``) plays a cut-down copy of the main job so
that numba's cache holds its kernels before the first run."""

import math

import sim
from mapupdate.warm import cut_route, short_scenario
from scenarios.catalog import find_scenario


def test_cut_route_stops_at_the_first_waypoint_past_the_length():
    route = ((0.0, 0.0), (1.0, 0.0), (3.0, 0.0), (3.0, 5.0))
    assert cut_route(route, 2.5) == ((0.0, 0.0), (1.0, 0.0), (3.0, 0.0))
    assert cut_route(route, 100.0) == route
    assert cut_route(route, 0.0) == route[:2]


def test_short_scenario_keeps_a_mapping_and_an_update_session_cut_short():
    full = sim.load_scenario(find_scenario(None))
    short = short_scenario(full, 4.0)
    assert [s.mapping for s in short.sessions] == [True, False]
    for s in short.sessions:
        original = next(o for o in full.sessions if o.name == s.name)
        assert s.route == original.route[:len(s.route)]
        legs = [math.dist(a, b) for a, b in zip(s.route, s.route[1:])]
        assert sum(legs[:-1]) < 4.0 and s.quick_route is None
    assert short.world == full.world and short.robot == full.robot
