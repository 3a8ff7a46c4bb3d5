"""The metrics of docs/design.md section 6, as frmd-host/src/eval/metrics.rs computes them, for paths
in any dimension (MetaWorld's hand moves in 3-D; frmd's built-in tasks are 2-D, where the
turning angle below is the same as frmd's)."""
from __future__ import annotations

import math

import numpy as np

NON_SMOOTH_CURVATURE = 1.0  # rad/m
MIN_SEGMENT = 1e-4  # m


def curvatures(path) -> np.ndarray:
    """kappa_i = theta_i / (0.5 (|p_i - p_{i-1}| + |p_{i+1} - p_i|)) at the interior points, rad/m.

    Points closer than MIN_SEGMENT to the previously kept point are dropped first. The turning
    angle theta between segments a and b is atan2(|a x b|, a . b) (in 2-D: |a_x b_y - a_y b_x|).
    """
    kept = []
    for p in np.asarray(path, dtype=np.float64):
        if not kept or np.linalg.norm(p - kept[-1]) >= MIN_SEGMENT:
            kept.append(p)
    out = []
    for p0, p1, p2 in zip(kept, kept[1:], kept[2:]):
        a, b = p1 - p0, p2 - p1
        dot = float(a @ b)
        if len(a) == 2:
            cross = abs(a[0] * b[1] - a[1] * b[0])
        elif len(a) == 3:
            cross = float(np.linalg.norm(np.cross(a, b)))
        else:
            cross = math.sqrt(max(float(a @ a) * float(b @ b) - dot * dot, 0.0))
        theta = math.atan2(cross, dot)
        out.append(theta / (0.5 * (np.linalg.norm(a) + np.linalg.norm(b))))
    return np.array(out)


def non_smooth_transitions(path) -> int:
    return int((curvatures(path) > NON_SMOOTH_CURVATURE).sum())


def rms_jerk(path, dt: float) -> float:
    """RMS of the third finite difference / dt^3 (vector norm), units/s^3; 0 under 4 points."""
    p = np.asarray(path, dtype=np.float64)
    if len(p) < 4 or dt <= 0:
        return 0.0
    jerk = (p[3:] - 3 * p[2:-1] + 3 * p[1:-2] - p[:-3]) / dt ** 3
    return float(math.sqrt((jerk ** 2).sum(axis=1).mean()))


def wilson_interval(successes: int, trials: int) -> list[float]:
    if trials == 0:
        return [0.0, 1.0]
    z = 1.959963984540054
    n, p = trials, successes / trials
    denom = 1 + z * z / n
    center = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return [max(center - half, 0.0), min(center + half, 1.0)]


def quantile(values, q: float) -> float:
    """Nearest-rank quantile; 0 for no values."""
    if len(values) == 0:
        return 0.0
    s = sorted(values)
    rank = math.ceil(min(max(q, 0.0), 1.0) * len(s))
    return float(s[min(max(rank, 1), len(s)) - 1])


def mean(values) -> float:
    return float(np.mean(values)) if len(values) else 0.0
