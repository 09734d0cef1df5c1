"""The simulator's people kernels against plain NumPy references (the beam caster and the flood
fill are tested in the lidar and ground-truth tests)."""

import numpy as np

from sim import _kernels as k
from sim import geometry as geo
from sim.people import SOCIAL_PARAMS


def social_reference(pos, vel, radius, desired, segs, circles, robot, params):
    tau, a_p, b_p, a_w, b_w, a_r, b_r, lam, cutoff = params
    acc = (desired - vel) / tau
    sp = np.hypot(desired[:, 0], desired[:, 1])
    heading = desired / np.where(sp > 0, sp, 1)[:, None]
    others = np.vstack([np.column_stack([pos, radius]), robot[None]])
    strength = np.r_[np.full(len(pos), a_p), a_r]
    rng_ = np.r_[np.full(len(pos), b_p), b_r]
    for i in range(len(pos)):
        d = pos[i] - others[:, :2]
        dist = np.hypot(d[:, 0], d[:, 1])
        ok = (dist <= cutoff + others[:, 2]) & (dist > 0)
        ok[i] = False
        n = d[ok] / dist[ok, None]
        w = lam + (1 - lam) * 0.5 * (1 - n @ heading[i])
        f = w * strength[ok] * np.exp(-(dist[ok] - radius[i] - others[ok, 2]) / rng_[ok])
        acc[i] += (f[:, None] * n).sum(axis=0)
        p, e = segs[:, :2], segs[:, 2:] - segs[:, :2]
        s = np.clip(((pos[i] - p) * e).sum(axis=1) / (e * e).sum(axis=1), 0, 1)
        d = pos[i] - p - s[:, None] * e
        dist = np.hypot(d[:, 0], d[:, 1])
        ok = dist <= cutoff
        f = a_w * np.exp(-(dist[ok] - radius[i]) / b_w)
        acc[i] += (f[:, None] * d[ok] / dist[ok, None]).sum(axis=0)
        d = pos[i] - circles[:, :2]
        dist = np.hypot(d[:, 0], d[:, 1])
        ok = dist - circles[:, 2] <= cutoff
        f = a_w * np.exp(-(dist[ok] - circles[ok, 2] - radius[i]) / b_w)
        acc[i] += (f[:, None] * d[ok] / dist[ok, None]).sum(axis=0)
    return acc


def test_social_forces_match_the_numpy_reference():
    rng = np.random.default_rng(0)
    boxes = np.array([[1.0, 1.0, 0.5, 0.3, 0.4], [3.0, 2.0, 0.4, 0.4, 0.0],
                      [-2.0, 0.5, 0.3, 1.0, 1.2], [9.0, 9.0, 0.5, 0.5, 0.0]])
    segs = geo.box_segments(boxes)
    circles = np.array([[0.0, 2.5, 0.3]])
    pos = rng.uniform(-3, 4, (7, 2))
    vel = rng.normal(0, 0.5, (7, 2))
    radius = rng.uniform(0.2, 0.3, 7)
    desired = rng.normal(0, 1, (7, 2))
    robot = np.array([0.5, 0.0, 0.35])
    acc = np.empty((7, 2))
    k.social_forces(pos, vel, radius, desired, boxes, segs, circles, robot, SOCIAL_PARAMS, acc)
    ref = social_reference(pos, vel, radius, desired, segs, circles, robot, SOCIAL_PARAMS)
    np.testing.assert_allclose(acc, ref, rtol=1e-9, atol=1e-9)


def test_people_step_caps_speed_and_tracks_progress():
    pos = np.array([[0.0, 0.0], [5.0, 5.0]])
    vel = np.array([[3.0, 0.0], [0.0, 0.0]])
    goals = np.array([[10.0, 0.0], [5.0, 5.2]])
    speed = np.array([1.0, 1.0])
    progress = np.array([[np.inf, 0.0, np.inf], [0.1, 2.0, 0.1]])
    out = np.empty((2, 2))
    k.people_step(pos, vel, np.array([0.25, 0.25]), speed, goals, np.zeros((0, 5)),
                  np.zeros((0, 4)), np.zeros((0, 3)), np.array([50.0, 50.0, 0.3]),
                  SOCIAL_PARAMS, 0.05, 1.3, progress, out)
    assert np.hypot(*out[0]) <= 1.3 + 1e-12
    assert progress[0].tolist() == [10.0, 0.0, 10.0]      # got closer: progress restarts
    np.testing.assert_allclose(progress[1], [0.1, 2.05, 0.2])  # no progress: the clock runs


def test_keep_out_leaves_every_disc_exactly_clear():
    rng = np.random.default_rng(1)
    boxes = np.array([[0.0, 0.0, 1.0, 0.5, 0.3], [4.0, 0.0, 0.5, 0.5, -0.8]])
    circles = np.array([[2.0, 3.0, 0.4]])
    pos = np.vstack([rng.uniform(-1.2, 1.2, (20, 2)), rng.uniform(3.3, 4.7, (20, 2)),
                     rng.uniform(1.5, 2.5, (10, 2)) + [0, 1.0]])
    radius = np.full(len(pos), 0.25)
    before = pos.copy()
    pushes = k.keep_out(pos, radius, boxes, circles, 0.0)
    d = np.minimum(geo.point_box_distance(pos, boxes).min(axis=1),
                   geo.point_circle_distance(pos, circles).min(axis=1))
    assert pushes > 0
    assert (d >= radius - 1e-9).all()
    clear = np.minimum(geo.point_box_distance(before, boxes).min(axis=1),
                       geo.point_circle_distance(before, circles).min(axis=1)) >= radius
    np.testing.assert_array_equal(pos[clear], before[clear])   # the clear ones never move
    moved = ~clear
    assert np.allclose(d[moved], radius[moved], atol=1e-9)   # pushed just clear, no further


def test_box_push_moves_out_through_the_nearest_face():
    box = np.array([0.0, 0.0, 1.0, 0.5, 0.0])
    assert np.allclose(k.box_push(0.9, 0.0, 0.2, box), (0.3, 0.0))
    assert np.allclose(k.box_push(0.0, -0.6, 0.2, box), (0.0, -0.1))
    assert k.box_push(0.0, 2.0, 0.2, box) == (0.0, 0.0)
