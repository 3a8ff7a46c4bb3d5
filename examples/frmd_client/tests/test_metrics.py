import math

import numpy as np

from frmd_client import metrics as m


def polyline(corners, step):
    out = [np.array(corners[0], float)]
    for a, b in zip(corners, corners[1:]):
        a, b = np.array(a, float), np.array(b, float)
        n = round(np.linalg.norm(b - a) / step)
        out += [a + (b - a) * k / n for k in range(1, n + 1)]
    return out


def test_same_cases_as_frmd():
    assert m.non_smooth_transitions(polyline([[0, 0], [2, 1]], 0.05)) == 0
    square = polyline([[0.5, 0], [1, 0], [1, 1], [0, 1], [0, 0], [0.5, 0]], 0.1)
    assert m.non_smooth_transitions(square) == 4
    assert abs(m.curvatures(square).max() - math.pi / 2 / 0.1) < 1e-9
    circle = lambda r, n: [[r * math.cos(2 * math.pi * k / n), r * math.sin(2 * math.pi * k / n)] for k in range(n + 1)]
    assert m.non_smooth_transitions(circle(2.0, 200)) == 0
    assert m.non_smooth_transitions(circle(0.5, 200)) == 199
    line = polyline([[0, 0], [1, 0]], 0.1)
    assert m.non_smooth_transitions(line + [line[-1]] * 5 + polyline([[1, 0], [2, 0]], 0.1)[1:]) == 0
    dt = 0.1
    cubic = [[(k * dt) ** 3, 0.0] for k in range(20)]
    assert abs(m.rms_jerk(cubic, dt) - 6.0) < 1e-6 and m.rms_jerk(cubic[:3], dt) == 0
    lo, hi = m.wilson_interval(45, 50)
    assert abs(lo - 0.7864) < 1e-3 and abs(hi - 0.9565) < 1e-3
    assert m.wilson_interval(0, 0) == [0.0, 1.0]
    values = list(range(1, 101))
    assert (m.quantile(values, 0.5), m.quantile(values, 0.99), m.quantile([], 0.5)) == (50, 99, 0)


def test_three_d_paths_match_their_planar_copies():
    """A 2-D path embedded in any plane of 3-D space has the same counts and jerk."""
    square = np.array(polyline([[0.5, 0], [1, 0], [1, 1], [0, 1], [0, 0], [0.5, 0]], 0.1))
    rot, _ = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))
    lifted = np.c_[square, np.zeros(len(square))] @ rot.T + [0.3, -0.2, 1.0]
    assert np.allclose(m.curvatures(lifted), m.curvatures(square))
    assert m.non_smooth_transitions(lifted) == 4
    assert abs(m.rms_jerk(lifted, 0.1) - m.rms_jerk(square, 0.1)) < 1e-6
