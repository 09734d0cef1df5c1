"""Numba kernels of the simulator: exact beam casting, people's social forces, keeping people out
of objects, and the flood fill of the ground truth. Arrays and scalars only; the public code in
``sim.lidar``, ``sim.people`` and ``sim.groundtruth`` checks the arguments."""

import math

import numpy as np
from numba import njit

TWO_PI = 2.0 * math.pi


@njit(cache=True)
def _beam_window(lo, span, a0, inc, n, shift):
    """Indices [i0, i1) of the beams whose angle may fall in [lo, lo + span] (world angles),
    ``shift`` whole turns away; one beam of slack each side, the exact test decides."""
    rel = (lo - a0) % TWO_PI + shift * TWO_PI
    i0 = int(math.ceil(rel / inc)) - 1
    i1 = int(math.floor((rel + span) / inc)) + 2
    return max(i0, 0), min(i1, n)


@njit(cache=True)
def _hit_segment(x, y, cs, sn, seg):
    """Distance along the beam (x, y, direction cs, sn) to the segment, or inf."""
    px, py = seg[0], seg[1]
    ex, ey = seg[2] - px, seg[3] - py
    den = cs * ey - sn * ex
    if den == 0.0:
        return np.inf
    wx, wy = px - x, py - y
    t = (wx * ey - wy * ex) / den
    u = (wx * sn - wy * cs) / den
    if t > 0.0 and u >= 0.0 and u <= 1.0:
        return t
    return np.inf


@njit(cache=True)
def _hit_circle(dx, dy, c2, cs, sn):
    """Distance along the beam to a circle whose centre is (dx, dy) from the sensor, with
    c2 = |d|^2 - r^2 > 0 (sensor outside), or inf."""
    b = dx * cs + dy * sn
    disc = b * b - c2
    if b <= 0.0 or disc < 0.0:
        return np.inf
    return c2 / (b + math.sqrt(disc))   # = b - sqrt(disc), without the cancellation


@njit(cache=True)
def cast_scan(sensor, angle_min, inc, segs, circles, max_range, out):
    """Ranges of beams ``angle_min + i * inc`` (sensor frame) from ``sensor`` (x, y, yaw)
    to the first segment or circle; inf beyond ``max_range``. Each primitive is tested only by
    the beams in its angular window, and segments facing away from the sensor are skipped
    (segments are the outlines of counter-clockwise polygons)."""
    n = out.size
    x, y, a0 = sensor[0], sensor[1], sensor[2] + angle_min
    cs = np.cos(a0 + inc * np.arange(n))
    sn = np.sin(a0 + inc * np.arange(n))
    out[:] = np.inf
    every = inc <= 0.0 or n * inc > TWO_PI + 1e-9
    for k in range(segs.shape[0]):
        px, py, qx, qy = segs[k, 0], segs[k, 1], segs[k, 2], segs[k, 3]
        ex, ey = qx - px, qy - py
        if (x - px) * ey - (y - py) * ex <= 0.0:
            continue                                  # back face, or seen edge-on
        L2 = ex * ex + ey * ey
        s = min(max(((x - px) * ex + (y - py) * ey) / L2, 0.0), 1.0)
        if math.hypot(px + s * ex - x, py + s * ey - y) > max_range:
            continue
        ang_q = math.atan2(qy - y, qx - x)            # seen from the front, q comes first
        span = (math.atan2(py - y, px - x) - ang_q) % TWO_PI
        for shift in range(-1, 1):
            i0, i1 = (0, n) if every else _beam_window(ang_q, span, a0, inc, n, shift)
            for i in range(i0, i1):
                t = _hit_segment(x, y, cs[i], sn[i], segs[k])
                if t < out[i]:
                    out[i] = t
            if every:
                break
    for k in range(circles.shape[0]):
        dx, dy, r = circles[k, 0] - x, circles[k, 1] - y, circles[k, 2]
        c2 = dx * dx + dy * dy - r * r
        d = math.sqrt(dx * dx + dy * dy)
        if c2 <= 0.0 or d - r > max_range:
            continue                                  # sensor inside, or out of reach
        half = math.asin(r / d)
        for shift in range(-1, 1):
            i0, i1 = (0, n) if every else _beam_window(math.atan2(dy, dx) - half, 2 * half,
                                                       a0, inc, n, shift)
            for i in range(i0, i1):
                t = _hit_circle(dx, dy, c2, cs[i], sn[i])
                if t < out[i]:
                    out[i] = t
            if every:
                break
    for i in range(n):
        if out[i] > max_range:
            out[i] = np.inf


@njit(cache=True)
def cast_scans(sensors, angle_min, inc, segs, circles, max_range, out):
    """``cast_scan`` for many sensor poses (N, 3) into ``out`` (N, beams)."""
    for j in range(sensors.shape[0]):
        cast_scan(sensors[j], angle_min, inc, segs, circles, max_range, out[j])


@njit(cache=True)
def _repel(a, b, dist, weight, nx, ny):
    """Helbing's exponential repulsion a * exp(-dist / b) along (nx, ny), scaled by weight."""
    f = weight * a * math.exp(-dist / b)
    return f * nx, f * ny


@njit(cache=True)
def social_forces(pos, vel, radius, desired, boxes, segs, circles, robot, params, acc):
    """Acceleration (N, 2) of each person: relaxation towards the desired velocity plus
    exponential repulsion from the other people, the robot (x, y, radius), the outline
    segments (4B, 4) of the boxes (B, 5), box k owning segments 4k..4k+3, and circles (C, 3).

    ``params``: tau [s], people strength [m/s^2] and range [m], obstacle strength and range,
    robot strength and range, anisotropy lambda (weight of what is behind), cutoff [m]."""
    tau, a_p, b_p, a_w, b_w = params[0], params[1], params[2], params[3], params[4]
    a_r, b_r, lam, cutoff = params[5], params[6], params[7], params[8]
    n = pos.shape[0]
    for i in range(n):
        ax = (desired[i, 0] - vel[i, 0]) / tau
        ay = (desired[i, 1] - vel[i, 1]) / tau
        sp = math.hypot(desired[i, 0], desired[i, 1])
        hx, hy = (desired[i, 0] / sp, desired[i, 1] / sp) if sp > 0 else (0.0, 0.0)
        for j in range(n + 1):
            if j == i:
                continue
            if j < n:
                ox, oy, orad, a, b = pos[j, 0], pos[j, 1], radius[j], a_p, b_p
            else:
                ox, oy, orad, a, b = robot[0], robot[1], robot[2], a_r, b_r
            dx, dy = pos[i, 0] - ox, pos[i, 1] - oy
            d = math.hypot(dx, dy)
            if d > cutoff + orad or d == 0.0:
                continue
            nx, ny = dx / d, dy / d
            # people mind what is ahead more than what is behind them
            w = lam + (1.0 - lam) * 0.5 * (1.0 - (nx * hx + ny * hy))
            fx, fy = _repel(a, b, d - radius[i] - orad, w, nx, ny)
            ax += fx
            ay += fy
        for k in range(segs.shape[0]):
            b = k // 4
            if math.hypot(pos[i, 0] - boxes[b, 0], pos[i, 1] - boxes[b, 1]) > \
                    cutoff + radius[i] + math.hypot(boxes[b, 2], boxes[b, 3]):
                continue                    # the whole box is out of reach
            px, py = segs[k, 0], segs[k, 1]
            ex, ey = segs[k, 2] - px, segs[k, 3] - py
            s = min(max(((pos[i, 0] - px) * ex + (pos[i, 1] - py) * ey) / (ex * ex + ey * ey),
                        0.0), 1.0)
            dx, dy = pos[i, 0] - px - s * ex, pos[i, 1] - py - s * ey
            d = math.hypot(dx, dy)
            if d > cutoff or d == 0.0:
                continue
            fx, fy = _repel(a_w, b_w, d - radius[i], 1.0, dx / d, dy / d)
            ax += fx
            ay += fy
        for k in range(circles.shape[0]):
            dx, dy = pos[i, 0] - circles[k, 0], pos[i, 1] - circles[k, 1]
            d = math.hypot(dx, dy)
            if d - circles[k, 2] > cutoff or d == 0.0:
                continue
            fx, fy = _repel(a_w, b_w, d - circles[k, 2] - radius[i], 1.0, dx / d, dy / d)
            ax += fx
            ay += fy
        acc[i, 0] = ax
        acc[i, 1] = ay


@njit(cache=True)
def desired_velocities(pos, goals, speed, out):
    """Preferred speed (N,) towards each goal (N, 2), easing in over the last half metre so
    that nobody overshoots a turning point; returns the distances to the goals."""
    dist = np.empty(pos.shape[0])
    for i in range(pos.shape[0]):
        dx, dy = goals[i, 0] - pos[i, 0], goals[i, 1] - pos[i, 1]
        d = math.hypot(dx, dy)
        dist[i] = d
        f = speed[i] * min(1.0, 0.5 + d) / d if d > 1e-9 else 0.0
        out[i, 0] = dx * f
        out[i, 1] = dy * f
    return dist


@njit(cache=True)
def people_step(pos, vel, radius, speed, goals, boxes, segs, circles, robot, params, dt,
                speed_cap, progress, out):
    """The velocities (N, 2) people want after ``dt``: the social-force acceleration integrated
    once, capped at ``speed_cap`` times their preferred speed. ``progress`` (N, 3) holds each
    person's closest approach to their goal [m], the time since they last got 0.5 m closer [s]
    and their goal distance now [m], updated here."""
    desired = np.empty_like(pos)
    dist = desired_velocities(pos, goals, speed, desired)
    social_forces(pos, vel, radius, desired, boxes, segs, circles, robot, params, out)
    for i in range(pos.shape[0]):
        vx = vel[i, 0] + out[i, 0] * dt
        vy = vel[i, 1] + out[i, 1] * dt
        v = math.hypot(vx, vy)
        cap = speed_cap * speed[i]
        f = cap / v if v > cap else 1.0
        out[i, 0] = vx * f
        out[i, 1] = vy * f
        if dist[i] < progress[i, 0] - 0.5:
            progress[i, 0] = dist[i]
            progress[i, 1] = 0.0
        else:
            progress[i, 1] += dt
        progress[i, 2] = dist[i]


@njit(cache=True)
def box_push(px, py, r, box):
    """(dx, dy) that moves a disc (px, py, r) just clear of a box (x, y, hw, hh, yaw); (0, 0)
    when it is clear already."""
    c, s = math.cos(box[4]), math.sin(box[4])
    u = c * (px - box[0]) + s * (py - box[1])
    v = -s * (px - box[0]) + c * (py - box[1])
    cu = min(max(u, -box[2]), box[2])
    cv = min(max(v, -box[3]), box[3])
    du, dv = u - cu, v - cv
    d = math.hypot(du, dv)
    if d > 0.0:                      # centre outside: push along the outward direction
        if d >= r:
            return 0.0, 0.0
        mu, mv = du / d * (r - d), dv / d * (r - d)
    else:                            # centre inside: out through the nearest face
        gu, gv = box[2] - abs(u), box[3] - abs(v)
        if gu < gv:
            mu, mv = math.copysign(gu + r, u), 0.0
        else:
            mu, mv = 0.0, math.copysign(gv + r, v)
    return c * mu - s * mv, s * mu + c * mv


@njit(cache=True)
def keep_out(pos, radius, boxes, circles, margin):
    """Move discs (N, 2 positions, N radii) in place out of boxes (B, 5) and circles (C, 3),
    leaving ``margin`` [m] of clearance; repeated so that a push out of one object into a
    neighbour is corrected too. Returns how many pushes were needed."""
    pushes = 0
    for _ in range(4):
        moved = False
        for i in range(pos.shape[0]):
            r = radius[i] + margin
            for k in range(boxes.shape[0]):
                dx, dy = box_push(pos[i, 0], pos[i, 1], r, boxes[k])
                if dx != 0.0 or dy != 0.0:
                    pos[i, 0] += dx
                    pos[i, 1] += dy
                    moved = True
                    pushes += 1
            for k in range(circles.shape[0]):
                dx, dy = pos[i, 0] - circles[k, 0], pos[i, 1] - circles[k, 1]
                d = math.hypot(dx, dy)
                gap = circles[k, 2] + r - d
                if gap > 0.0:
                    nx, ny = (dx / d, dy / d) if d > 0 else (1.0, 0.0)
                    pos[i, 0] += gap * nx
                    pos[i, 1] += gap * ny
                    moved = True
                    pushes += 1
        if not moved:
            break
    return pushes


@njit(cache=True)
def flood_fill4(passable, r0, c0, out):
    """Mark in ``out`` the cells of ``passable`` (H, W) 4-connected to (r0, c0)."""
    h, w = passable.shape
    out[:, :] = False
    if not (0 <= r0 < h and 0 <= c0 < w) or not passable[r0, c0]:
        return
    stack = np.empty(h * w, np.int64)
    stack[0] = r0 * w + c0
    out[r0, c0] = True
    top = 1
    while top > 0:
        top -= 1
        r = stack[top] // w
        c = stack[top] - r * w
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            rr, cc = r + dr, c + dc
            if 0 <= rr < h and 0 <= cc < w and passable[rr, cc] and not out[rr, cc]:
                out[rr, cc] = True
                stack[top] = rr * w + cc
                top += 1
