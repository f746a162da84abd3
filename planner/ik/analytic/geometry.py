"""Axis and plane geometry shared by the closed-form families, and their numeric tolerances.

The families read their chain's axes (:mod:`planner.geometry.chain`) and compare them with
ideal directions (vertical, parallel, perpendicular) by :func:`angle_to_line` and
:func:`angle_to_plane`; a two-link arm's reach within its elbow's range is
:func:`reach_interval`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "SINGULAR_TOL",
    "LENGTH_TOL",
    "ORIENTATION_TOL",
    "angle_to_line",
    "angle_to_plane",
    "wrap_pi",
    "reach_interval",
]

PI = math.pi
TWO_PI = 2.0 * math.pi

#: A stretched/folded elbow with |sin| below this is set exactly singular (the position changes
#: by its square only); also the relative distance to the yaw axis flagged singular.
SINGULAR_TOL = 1e-7
#: Relative (to the arm's size) length tolerance: reach round-off, the yaw axis.
LENGTH_TOL = 1e-12
#: Orientation residual [rad] up to which an asked orientation counts as achieved.
ORIENTATION_TOL = 1e-7


def angle_to_line(a: np.ndarray, b: np.ndarray) -> float:
    """Angle [rad] between the lines along unit vectors a and b (0 when parallel or opposite).

    Args:
        a: Unit vector, shape (3,).
        b: Unit vector, shape (3,).
    """
    return math.asin(min(1.0, float(np.linalg.norm(np.cross(a, b)))))


def angle_to_plane(a: np.ndarray, normal: np.ndarray) -> float:
    """Angle [rad] between unit vector a and the plane with unit normal `normal`.

    Args:
        a: Unit vector, shape (3,).
        normal: Unit normal of the plane, shape (3,).
    """
    return math.asin(min(1.0, abs(float(a @ normal))))


def wrap_pi(x):
    """Angle(s) [rad] wrapped into [-pi, pi) (a float or an array of any shape)."""
    return (x + PI) % TWO_PI - PI


def reach_interval(l1: float, l2, delta, lo: float, hi: float, sign: float):
    """Reach bounds of a 2-link whose relative angle is ``sign * q + delta``, q in [lo, hi].

    Args:
        l1: First link length [m].
        l2: Second link length [m], a float or an array.
        delta: Relative angle at q = 0 [rad], a float or an array (broadcast with `l2`).
        lo: Lower limit of q [rad] (may be -inf).
        hi: Upper limit of q [rad] (may be +inf).
        sign: +1 or -1, the direction q turns the second link.

    Returns:
        (r_min, r_max) [m], arrays of the broadcast shape of `l2` and `delta` (0-d for floats).
    """
    a, b = sorted((sign * lo, sign * hi))
    width = b - a
    e_lo = np.asarray(a + delta, dtype=float)
    e_hi = np.asarray(b + delta, dtype=float)
    if not math.isfinite(width) or width >= TWO_PI:
        cmax = np.ones_like(e_lo)
        cmin = -np.ones_like(e_lo)
    else:
        has_zero = np.floor(e_hi / TWO_PI) >= np.ceil(e_lo / TWO_PI)
        has_pi = np.floor((e_hi - PI) / TWO_PI) >= np.ceil((e_lo - PI) / TWO_PI)
        ends_max = np.maximum(np.cos(e_lo), np.cos(e_hi))
        ends_min = np.minimum(np.cos(e_lo), np.cos(e_hi))
        cmax = np.where(has_zero, 1.0, ends_max)
        cmin = np.where(has_pi, -1.0, ends_min)
    base = l1 * l1 + l2 * l2
    r_max = np.sqrt(np.maximum(base + 2 * l1 * l2 * cmax, 0.0))
    r_min = np.sqrt(np.maximum(base + 2 * l1 * l2 * cmin, 0.0))
    return r_min, r_max
