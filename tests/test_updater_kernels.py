"""Every kernel of updater._kernels against a plain NumPy / Python reference, on seeded random
input. The references are written for clarity, not speed, and share no code with the kernels."""

from __future__ import annotations

import math
from collections import deque

import numpy as np
import pytest

from updater import _kernels as K

FREE, OCC, UNK = 0, 100, -1


# --- references -------------------------------------------------------------------------------
def ref_segment_cells(x0, y0, x1, y1, height, width):
    """Cells (row, col) the segment crosses with positive length, from the start, clipped."""
    dx, dy = x1 - x0, y1 - y0
    if dx == 0 and dy == 0:
        r, c = math.floor(y0), math.floor(x0)
        return [(r, c)] if 0 <= r < height and 0 <= c < width else []
    found = []
    for r in range(max(0, math.floor(min(y0, y1))), min(height, math.floor(max(y0, y1)) + 1)):
        for c in range(max(0, math.floor(min(x0, x1))), min(width, math.floor(max(x0, x1)) + 1)):
            t0, t1 = 0.0, 1.0
            for p, d, lo, hi in ((x0, dx, c, c + 1), (y0, dy, r, r + 1)):
                if d == 0:
                    if not lo <= p < hi:
                        t0, t1 = 1.0, 0.0
                else:
                    a, b = (lo - p) / d, (hi - p) / d
                    t0, t1 = max(t0, min(a, b)), min(t1, max(a, b))
            if t1 - t0 > 1e-9 or (t1 >= t0 and (c <= x0 < c + 1 and r <= y0 < r + 1)):
                found.append((t0, r, c))
    return [(r, c) for _, r, c in sorted(found)]


def ref_expected_point(data, x0, y0, a, max_len):
    """March the ray cell by cell: the entry point of the first occupied-or-unknown cell, or the
    point where it leaves the grid; None when nothing blocks within max_len."""
    h, w = data.shape
    x1, y1 = x0 + max_len * math.cos(a), y0 + max_len * math.sin(a)
    for r, c in ref_segment_cells(x0, y0, x1, y1, h, w):
        if data[r, c] != FREE:
            ts = [0.0]
            for p, d, lo, hi in ((x0, math.cos(a), c, c + 1), (y0, math.sin(a), r, r + 1)):
                if d != 0:
                    ts.append(min((lo - p) / d, (hi - p) / d))
            t = max(ts)
            return x0 + t * math.cos(a), y0 + t * math.sin(a)
    if 0 <= x1 < w and 0 <= y1 < h:
        return None
    ts = []
    for p, d, lo, hi in ((x0, math.cos(a), 0, w), (y0, math.sin(a), 0, h)):
        if d != 0:
            ts.append(max((lo - p) / d, (hi - p) / d))
    t = min(ts)
    return x0 + t * math.cos(a), y0 + t * math.sin(a)


def ref_disc_is_free(data, px, py, rad):
    h, w = data.shape
    for r in range(math.floor(py - rad) - 1, math.floor(py + rad) + 2):
        for c in range(math.floor(px - rad) - 1, math.floor(px + rad) + 2):
            qx, qy = np.clip(px, c, c + 1), np.clip(py, r, r + 1)
            if (qx - px) ** 2 + (qy - py) ** 2 < rad**2:
                if not (0 <= r < h and 0 <= c < w) or data[r, c] != FREE:
                    return False
    return True


def ref_popcount(v):
    return bin(int(v)).count("1")


def random_map(rng, h=40, w=50, p_occ=0.08, p_unk=0.05):
    data = np.full((h, w), FREE, np.int8)
    u = rng.random((h, w))
    data[u < p_occ] = OCC
    data[(u >= p_occ) & (u < p_occ + p_unk)] = UNK
    return data


def random_hits(rng, n, h, w, sensor):
    ranges = rng.uniform(0.05, 2.0, n)                    # [m]
    a = sensor[2] + rng.uniform(-math.pi, math.pi, n)
    res = 0.05
    return ranges, sensor[0] + ranges / res * np.cos(a), sensor[1] + ranges / res * np.sin(a)


# --- bits -------------------------------------------------------------------------------------
def test_popcount_and_bits():
    for v in [0, 1, 0x3FF, 0xFFFF, 0x8001, 0x5555, 12345]:
        assert K.popcount16(np.uint16(v)) == ref_popcount(v)
    bits = np.zeros(4, np.uint8)
    assert K.test_and_set(bits, 13) and not K.test_and_set(bits, 13)
    assert K.bit_get(bits, 13) == 1 and K.bit_get(bits, 12) == 0
    assert np.unpackbits(bits, bitorder="little").nonzero()[0].tolist() == [13]


# --- 1. beam classifier -----------------------------------------------------------------------
def test_beam_endpoints():
    ranges = np.array([1.0, np.nan, np.inf, -1.0, 0.0, 0.01, 2.0, 17.99, 18.0, 25.0], np.float32)
    sensor = np.array([10.3, 20.7, 0.4])
    geom = np.array([-1.0, 0.1, 0.0, 18.0])
    n = ranges.size
    r, hx, hy, valid = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n, np.bool_)
    n_valid, walk, box = K.beam_endpoints(ranges, sensor, geom, 0.05, r, hx, hy, valid)
    expect = [True, False, False, False, False, True, True, True, False, False]
    assert valid.tolist() == expect and n_valid == 4
    a = 0.4 - 1.0 + 0.1 * np.arange(n)
    rr = ranges.astype(np.float64)
    np.testing.assert_allclose(hx[valid], 10.3 + rr[valid] / 0.05 * np.cos(a[valid]), atol=1e-9)
    np.testing.assert_allclose(hy[valid], 20.7 + rr[valid] / 0.05 * np.sin(a[valid]), atol=1e-9)
    cols, rows = np.floor(hx[valid]).astype(int), np.floor(hy[valid]).astype(int)
    assert walk == int(np.sum(np.abs(cols - 10) + np.abs(rows - 20) + 7))
    assert box == (max(cols.max(), 10) - min(cols.min(), 10) + 3) * \
        (max(rows.max(), 20) - min(rows.min(), 20) + 3)
    # range_min of the scan applies too
    geom[2] = 0.5
    K.beam_endpoints(ranges, sensor, geom, 0.05, r, hx, hy, valid)
    assert not valid[5] and valid[0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_cast_virtual_against_cell_march(seed):
    rng = np.random.default_rng(seed)
    data = random_map(rng, p_occ=0.03, p_unk=0.02)
    sensor = np.array([rng.uniform(5, 45), rng.uniform(5, 35), rng.uniform(-3, 3)])
    data[int(sensor[1]), int(sensor[0])] = FREE
    m = 300
    ex, ey, ok = np.zeros(m), np.zeros(m), np.zeros(m, np.bool_)
    step = 2 * math.pi / m
    max_len = rng.uniform(10, 40)
    K.cast_virtual(data, sensor, -math.pi, step, max_len, ex, ey, ok)
    for j in range(m):
        p = ref_expected_point(data, sensor[0], sensor[1], sensor[2] - math.pi + j * step, max_len)
        assert ok[j] == (p is not None)
        if p is not None:
            assert abs(ex[j] - p[0]) < 1e-6 and abs(ey[j] - p[1]) < 1e-6


def ref_classify(hx, hy, r, valid, ex, ey, eok, ratio, half, wrap, dpar, res):
    m = len(ex)
    out = []
    for i in range(len(hx)):
        if not valid[i]:
            out.append(False)
            continue
        d = min(dpar[0] + dpar[2] * (r[i] - dpar[1]), dpar[3]) / res
        js = [i * ratio + o for o in range(-half, half + 1)]
        js = [j % m for j in js] if wrap else [j for j in js if 0 <= j < m]
        out.append(not any(eok[j] and math.hypot(hx[i] - ex[j], hy[i] - ey[j]) < d for j in js))
    return np.array(out)


@pytest.mark.parametrize("ratio,wrap", [(1, False), (1, True), (2, False), (3, True)])
def test_classify_against_brute_force(ratio, wrap):
    rng = np.random.default_rng(ratio * 10 + wrap)
    n = 120
    m = n * ratio
    ex, ey = rng.uniform(0, 20, m), rng.uniform(0, 20, m)
    eok = rng.random(m) > 0.2
    # hit points near expected points some of the time, elsewhere otherwise
    src = (np.arange(n) * ratio + rng.integers(-12, 13, n)) % m
    near = rng.random(n) < 0.6
    hx = np.where(near, ex[src] + rng.normal(0, 3, n), rng.uniform(0, 20, n))
    hy = np.where(near, ey[src] + rng.normal(0, 3, n), rng.uniform(0, 20, n))
    r = rng.uniform(0.1, 15, n)
    valid = rng.random(n) > 0.1
    dpar = np.array([0.15, 0.2, 0.013265, 0.30])
    out = np.zeros(n, np.bool_)
    count = K.classify(hx, hy, r, valid, ex, ey, eok, ratio, 6, wrap, dpar, 0.05, out)
    expect = ref_classify(hx, hy, r, valid, ex, ey, eok, ratio, 6, wrap, dpar, 0.05)
    assert out.tolist() == expect.tolist() and count == expect.sum()
    assert 10 < count < n - 10      # both outcomes exercised


def test_classify_window_wraps_only_when_asked():
    n = 100
    ex, ey = np.full(n, 50.0), np.full(n, 50.0)
    eok = np.zeros(n, np.bool_)
    eok[n - 2] = True                       # the only expected point: two beams before beam 0
    ex[n - 2], ey[n - 2] = 10.0, 10.0
    hx, hy = np.array([10.1] + [90.0] * (n - 1)), np.array([10.0] + [90.0] * (n - 1))
    r, valid = np.full(n, 1.0), np.ones(n, np.bool_)
    dpar = np.array([0.15, 0.2, 0.013265, 0.30])
    out = np.zeros(n, np.bool_)
    K.classify(hx, hy, r, valid, ex, ey, eok, 1, 4, False, dpar, 0.05, out)
    assert out[0]
    K.classify(hx, hy, r, valid, ex, ey, eok, 1, 4, True, dpar, 0.05, out)
    assert not out[0]


def ref_run_filter(change, min_run, wrap):
    n = len(change)
    keep = np.zeros(n, bool)
    if wrap and n and all(change):
        keep[:] = n >= min_run
        return keep
    runs, start = [], None
    for i in range(n):
        if change[i] and start is None:
            start = i
        if not change[i] and start is not None:
            runs.append(list(range(start, i)))
            start = None
    if start is not None:
        runs.append(list(range(start, n)))
    if wrap and len(runs) > 1 and runs[0][0] == 0 and runs[-1][-1] == n - 1:
        runs[0] = runs.pop() + runs[0]
    for run in runs:
        if len(run) >= min_run:
            keep[run] = True
    return keep


@pytest.mark.parametrize("wrap", [False, True])
def test_run_filter_against_reference(wrap):
    rng = np.random.default_rng(3)
    out = np.zeros(60, np.bool_)
    for trial in range(300):
        change = rng.random(60) < rng.uniform(0.2, 0.9)
        min_run = int(rng.integers(1, 6))
        kept = K.run_filter(change, min_run, wrap, out)
        expect = ref_run_filter(change, min_run, wrap)
        assert out.tolist() == expect.tolist() and kept == expect.sum()
    change = np.ones(60, np.bool_)
    assert K.run_filter(change, 3, True, out) == 60 and out.all()


def test_run_filter_wrap_joins_scan_ends():
    change = np.zeros(20, np.bool_)
    change[[0, 1, 19]] = True
    out = np.zeros(20, np.bool_)
    assert K.run_filter(change, 3, False, out) == 0
    assert K.run_filter(change, 3, True, out) == 3 and out[[0, 1, 19]].all()


def ref_verdicts(valid, keep, n_skip, wrap):
    n = len(valid)
    out = []
    for i in range(n):
        if keep[i]:
            out.append(K.CHANGE)
        elif not valid[i]:
            out.append(K.INVALID)
        else:
            near = [j for j in range(n) if keep[j] and
                    (min(abs(i - j), n - abs(i - j)) if wrap else abs(i - j)) <= n_skip]
            out.append(K.SKIPPED if near else K.UNCHANGED)
    return out


@pytest.mark.parametrize("wrap", [False, True])
def test_beam_verdicts_against_reference(wrap):
    rng = np.random.default_rng(4)
    out = np.zeros(50, np.int8)
    for trial in range(200):
        valid = rng.random(50) > 0.2
        keep = valid & (rng.random(50) < 0.1)
        n_skip = int(rng.integers(0, 4))
        K.beam_verdicts(valid, keep, n_skip, wrap, out)
        assert out.tolist() == ref_verdicts(valid, keep, n_skip, wrap)


def test_invalid_beam_after_change_does_not_stop_unchanged_flags():
    # The authors' defect: an invalid beam two past a change silenced the rest of the scan.
    valid = np.ones(12, np.bool_)
    valid[5] = False
    keep = np.zeros(12, np.bool_)
    keep[3] = True
    out = np.zeros(12, np.int8)
    K.beam_verdicts(valid, keep, 2, False, out)
    assert out.tolist() == [1, 2, 2, 3, 2, 0, 1, 1, 1, 1, 1, 1]


# --- 2./3. evaluators -------------------------------------------------------------------------
def test_disc_is_free_against_brute_force():
    rng = np.random.default_rng(5)
    data = random_map(rng, h=30, w=30, p_occ=0.01, p_unk=0.01)
    for trial in range(2000):
        px, py = rng.uniform(-1, 31, 2)
        rad = rng.uniform(0.1, 5)
        assert K.disc_is_free(data, px, py, rad) == ref_disc_is_free(data, px, py, rad)


def ref_flag_changed(data, hx, hy, r, verdict, sensor, tpar, res):
    h, w = data.shape
    cells, n_new = [], 0
    for i in range(len(hx)):
        if verdict[i] != K.CHANGE:
            continue
        tol = tpar[0] + (tpar[1] - tpar[0]) * min(r[i] / tpar[2], 1.0)
        if ref_disc_is_free(data, hx[i], hy[i], tol / res):
            cell = math.floor(hy[i]) * w + math.floor(hx[i])
            if cell not in cells:
                cells.append(cell)
                n_new += 1
        skip = max(tpar[3] * r[i], tpar[4])
        if skip >= r[i]:
            continue
        f = 1 - skip / r[i]
        tx, ty = sensor[0] + f * (hx[i] - sensor[0]), sensor[1] + f * (hy[i] - sensor[1])
        walk = ref_segment_cells(sensor[0], sensor[1], tx, ty, h, w)
        if 0 <= tx < w and 0 <= ty < h:
            walk = walk[:-1]
        for rr, cc in walk:
            if data[rr, cc] != FREE and rr * w + cc not in cells:
                cells.append(rr * w + cc)
    return cells, n_new


def ref_flag_unchanged(data, hx, hy, r, verdict, sensor, free_fraction, free_margin=0.0):
    h, w = data.shape
    cells = []
    for i in range(len(hx)):
        if verdict[i] != K.UNCHANGED:
            continue
        frac = free_fraction
        if free_margin > 0 and r[i] > free_margin:
            frac = max(frac, 1 - free_margin / r[i])
        r0, c0 = math.floor(hy[i]), math.floor(hx[i])
        for dr, dc in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):
            rr, cc = r0 + dr, c0 + dc
            if 0 <= rr < h and 0 <= cc < w and data[rr, cc] != FREE and rr * w + cc not in cells:
                cells.append(rr * w + cc)
        tx, ty = sensor[0] + frac * (hx[i] - sensor[0]), sensor[1] + frac * (hy[i] - sensor[1])
        for rr, cc in ref_segment_cells(sensor[0], sensor[1], tx, ty, h, w):
            if data[rr, cc] == FREE and rr * w + cc not in cells:
                cells.append(rr * w + cc)
    return cells


def _evaluator_input(seed):
    rng = np.random.default_rng(seed)
    data = random_map(rng, p_occ=0.05, p_unk=0.03)
    sensor = np.array([rng.uniform(10, 40), rng.uniform(10, 30), 0.3])
    r, hx, hy = random_hits(rng, 80, *data.shape, sensor)
    verdict = rng.choice(np.array([K.INVALID, K.UNCHANGED, K.SKIPPED, K.CHANGE], np.int8), 80)
    return data, sensor, r, hx, hy, verdict


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_flag_changed_against_reference(seed):
    data, sensor, r, hx, hy, verdict = _evaluator_input(seed)
    data[data.shape[0] // 2:] = FREE      # an open half, where new obstacles can be flagged
    tpar = np.array([0.10, 0.20, 10.0, 0.02, 0.15])
    marks = np.zeros((data.size + 7) // 8, np.uint8)
    rows, cols = np.zeros(300, np.int64), np.zeros(300, np.int64)
    out = np.zeros(5000, np.int32)
    n, n_new = K.flag_changed(data, hx, hy, r, verdict, sensor, tpar, 0.05, marks, rows, cols,
                              out)
    cells, expect_new = ref_flag_changed(data, hx, hy, r, verdict, sensor, tpar, 0.05)
    assert sorted(out[:n].tolist()) == sorted(cells) and n_new == expect_new
    assert n_new > 0 and n > n_new
    # every listed cell is marked, and only those
    assert sorted(np.flatnonzero(np.unpackbits(marks, bitorder="little"))) == sorted(cells)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
@pytest.mark.parametrize("free_fraction, free_margin", [(0.98, 0.0), (0.9, 0.075)])
def test_flag_unchanged_against_reference(seed, free_fraction, free_margin):
    data, sensor, r, hx, hy, verdict = _evaluator_input(seed)
    marks = np.zeros((data.size + 7) // 8, np.uint8)
    rows, cols = np.zeros(300, np.int64), np.zeros(300, np.int64)
    out = np.zeros(5000, np.int32)
    n = K.flag_unchanged(data, hx, hy, r, verdict, sensor, free_fraction, free_margin, marks,
                         rows, cols, out)
    cells = ref_flag_unchanged(data, hx, hy, r, verdict, sensor, free_fraction, free_margin)
    assert sorted(out[:n].tolist()) == sorted(cells) and n > 0


# --- buffers and decision ---------------------------------------------------------------------
def ref_decide_all(hist, data, mask, threshold, support):
    n = np.vectorize(lambda v: ref_popcount(int(v) & mask))(hist)
    changed = n >= threshold
    if support:
        occ = data != FREE
        strong = n >= threshold
        h, w = data.shape
        s = np.zeros_like(n)
        pad_strong = np.pad(strong, 1)
        pad_occ = np.pad(occ, 1)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                if dr or dc:
                    nb_strong = pad_strong[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
                    nb_occ = pad_occ[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
                    s += nb_strong & (nb_occ == occ)
        changed |= n + s >= threshold
    return changed


def test_push_flags_against_reference():
    rng = np.random.default_rng(6)
    hist = rng.integers(0, 1024, 500).astype(np.uint16)
    hist[rng.random(500) < 0.5] = 0
    before = hist.copy()
    changed = rng.choice(500, 80, replace=False).astype(np.int32)
    unchanged = rng.choice(500, 200, replace=False).astype(np.int32)
    ch_marks, un_marks = np.full(63, 255, np.uint8), np.full(63, 255, np.uint8)
    moved = np.zeros(280, np.int32)
    n = K.push_flags(hist, changed, 80, unchanged, 200, 0x3FF, 7, ch_marks, un_marks, moved)
    expect = before.astype(int)
    log = []
    for idx, flag in [(i, 1) for i in changed] + [(i, 0) for i in unchanged]:
        old = expect[idx]
        expect[idx] = ((old << 1) | flag) & 0x3FF
        p0, p1 = ref_popcount(old), ref_popcount(expect[idx])
        if p0 != p1:
            log.append(-1 - idx if (p0 >= 7) != (p1 >= 7) else idx)
    assert hist.tolist() == expect.tolist()
    assert moved[:n].tolist() == log
    assert not ch_marks[changed >> 3].any() and not un_marks[unchanged >> 3].any()


@pytest.mark.parametrize("support", [False, True])
def test_decide_incremental_equals_full_map(support):
    rng = np.random.default_rng(7 + support)
    data = random_map(rng, h=30, w=30, p_occ=0.3, p_unk=0.1)
    flat = data.reshape(-1)
    hist = np.zeros(data.size, np.uint16)
    decided = np.zeros((data.size + 7) // 8, np.uint8)
    marks = np.zeros_like(decided), np.zeros_like(decided)
    moved = np.zeros(2000, np.int32)
    count = peak = 0
    centres = rng.integers(0, 26, (3, 2))
    for scan in range(40):
        # flags in a few blobs, so that neighbours reach the threshold together
        r0, c0 = centres[scan % 3]
        cells = ((r0 + rng.integers(0, 5, 60)) * 30 + c0 + rng.integers(0, 5, 60))
        cells = np.unique(cells).astype(np.int32)
        p = 0.85 if scan < 25 else 0.3
        ch = cells[rng.random(cells.size) < p]
        un = cells[rng.random(cells.size) < 0.3]
        n = K.push_flags(hist, ch, ch.size, un, un.size, 0x3FF, 7, marks[0], marks[1], moved)
        count += K.decide(hist, flat, decided, moved, n, 30, 0x3FF, 7, support)
        expect = ref_decide_all(hist.reshape(30, 30), data, 0x3FF, 7, support)
        got = np.unpackbits(decided, bitorder="little")[:900].reshape(30, 30).astype(bool)
        assert (got == expect).all() and count == expect.sum()
        peak = max(peak, count)
    assert peak > count > 0           # cells changed, and some changed back
    full = np.zeros_like(decided)
    assert K.decide_all(hist, flat, full, 30, 0x3FF, 7, support) == count
    assert (full == decided).all()


def test_neighbour_support_rule():
    # A free cell with n = 4 and three free 8-neighbours at n >= 7 reaches 4 + 3 = 7.
    data = np.zeros((5, 5), np.int8)
    hist = np.zeros(25, np.uint16)
    hist[12] = 0b1111
    for j in (6, 7, 8):
        hist[j] = 0b1111111
    decided = np.zeros(4, np.uint8)
    assert K.decide_cell(hist, data.reshape(-1), decided, 12, 5, 0x3FF, 7, True) == 1
    data[1, 1] = OCC         # one supporter of another state in M: 4 + 2 < 7
    decided[:] = 0
    assert K.decide_cell(hist, data.reshape(-1), decided, 12, 5, 0x3FF, 7, True) == 0
    assert K.decide_cell(hist, data.reshape(-1), decided, 12, 5, 0x3FF, 7, False) == 0


# --- output and last check --------------------------------------------------------------------
def ref_enclosed(data, max_cells):
    h, w = data.shape
    seen = np.zeros_like(data, bool)
    out = np.zeros_like(data, bool)
    for r in range(h):
        for c in range(w):
            if data[r, c] >= 0 or seen[r, c]:
                continue
            comp, queue = [], deque([(r, c)])
            seen[r, c] = True
            while queue:
                y, x = queue.popleft()
                comp.append((y, x))
                for dy in (-1, 0, 1):
                    for dx in (-1, 0, 1):
                        yy, xx = y + dy, x + dx
                        if 0 <= yy < h and 0 <= xx < w and not seen[yy, xx] and data[yy, xx] < 0:
                            seen[yy, xx] = True
                            queue.append((yy, xx))
            border = any(y in (0, h - 1) or x in (0, w - 1) for y, x in comp)
            if not border and len(comp) <= max_cells:
                for y, x in comp:
                    out[y, x] = True
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_enclosed_unknown_against_bfs(seed):
    from updater.steps import enclosed_unknown

    rng = np.random.default_rng(seed)
    data = random_map(rng, h=45, w=38, p_occ=0.3, p_unk=0.35)
    for max_cells in (3, 20, 10**6):
        bits, marked = enclosed_unknown(data, max_cells)
        got = np.unpackbits(bits, bitorder="little")[:data.size].reshape(data.shape).astype(bool)
        expect = ref_enclosed(data, max_cells)
        assert (got == expect).all() and marked == expect.sum()
    assert expect.any()


def test_enclosed_unknown_diagonal_leak_is_not_enclosed():
    data = np.zeros((7, 7), np.int8)
    data[1:6, 1:6] = OCC
    data[2:5, 2:5] = UNK                 # a sealed interior
    from updater.steps import enclosed_unknown

    bits, marked = enclosed_unknown(data, 100)
    assert marked == 9
    data[0, 0] = UNK                     # unknown at the border ...
    data[1, 1] = UNK                     # ... touching the interior only through corners
    bits, marked = enclosed_unknown(data, 100)
    assert marked == 0


def ref_apply(data, decided, enclosed, close):
    out = data.copy()
    out[decided & (data == FREE)] = OCC
    out[decided & (data != FREE)] = FREE
    if close:
        freed = np.pad(decided & (data != FREE), 1)
        h, w = data.shape
        near = np.zeros_like(decided)
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                near |= freed[1 + dr:1 + dr + h, 1 + dc:1 + dc + w]
        out[near & enclosed & ~decided] = OCC
    return out


@pytest.mark.parametrize("close", [False, True])
def test_apply_changes_against_reference(close):
    rng = np.random.default_rng(8)
    data = random_map(rng, h=33, w=41, p_occ=0.2, p_unk=0.3)
    decided = rng.random(data.shape) < 0.1
    enclosed = (data == UNK) & (rng.random(data.shape) < 0.7)
    pack = lambda m: np.packbits(m.reshape(-1), bitorder="little")  # noqa: E731
    out = data.reshape(-1).copy()
    closed = K.apply_changes(data.reshape(-1), pack(decided), pack(enclosed), 41, close, out)
    expect = ref_apply(data, decided, enclosed, close)
    assert (out.reshape(data.shape) == expect).all()
    assert closed == ((expect == OCC) & (data == UNK) & ~decided).sum()
    assert closed > 0 if close else closed == 0
