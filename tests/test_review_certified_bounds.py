"""Fuzz checks of the certified bounds against independent references (review of the panda speed-ups).

bounded_conditioning's per-row values against the measure computed here directly from
Pinocchio's frame Jacobian and NumPy's SVD (not Robot.conditioning): every row at most the true
inverse condition number and manipulability (up to the references' rounding), on random DH arms,
the bundled arms and ur5 / panda / z1, along walks chosen to stress the compiled steps' row
projection (rows off the straight line between anchors, rows going back and forth along it, slow
starts, huge angles) and near singularities. And the manipulability bound _shifted_det (and its
compiled twin) against det(M - c I) of random symmetric matrices with the assumed spectrum.
"""

from __future__ import annotations

import ctypes
import subprocess

import numpy as np
import pinocchio as pin
import pytest
from dh_arms import BUNDLED, dh_descriptions, property_settings, robot_from_description
from hypothesis import given
from hypothesis import strategies as st

from planner.core.certificates import grams
from planner.motion.limits import JointLimits
from planner.motion.plan import plan_trajectory
from planner.motion.singularity import _shifted_det, bounded_conditioning, inverse_condition_threshold

from conftest import HAVE_EXAMPLE_ROBOT_DATA, get_robot

ARMS = list(BUNDLED) + (["ur5", "panda", "z1"] if HAVE_EXAMPLE_ROBOT_DATA else [])
COMPILED = grams(np.zeros((1, 1, 1))) is not None
# Relative slack for the references' own rounding (Pinocchio's and NumPy's against the kernel's).
SLACK = 1e-10


def _reference(robot, q: np.ndarray, task: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse condition number, manipulability and its rounding, from Pinocchio and NumPy directly."""
    model, data = robot.model, pin.Data(robot.model)
    fid = robot.tip_frame_id
    length = robot.characteristic_length
    prismatic = np.array([kind == "prismatic" for kind in robot.joint_kinds])
    inv, man, noise = np.empty(len(q)), np.empty(len(q)), np.empty(len(q))
    for r, row in enumerate(q):
        full = pin.computeFrameJacobian(model, data, robot._pin_q(row), fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        raw = np.reshape(full, (6, -1))[:3] if task == "position" else np.reshape(full, (6, -1)).copy()
        scaled = raw.copy()
        scaled[:, prismatic] *= length
        if task == "pose":
            scaled[3:] *= length
        k = min(raw.shape)
        s = np.linalg.svd(scaled, compute_uv=False)[:k]
        inv[r] = s[-1] / s[0] if s[0] > 0 else 0.0
        s_raw = np.linalg.svd(raw, compute_uv=False)[:k]
        man[r] = np.prod(s_raw)
        # The rounding of that product: a few ulp of the largest singular value in each factor.
        noise[r] = 1e-13 * s_raw[0] ** k
    return inv, man, noise


def _check_below(robot, q: np.ndarray, task: str, threshold: float, keep: np.ndarray, reference) -> None:
    inv, man = bounded_conditioning(robot, q, task, threshold, keep)
    inv_ref, man_ref, noise = reference
    # An SVD's rounding is a few ulp of the largest singular value.
    scale_inv = SLACK * inv_ref + 1e-14
    scale_man = SLACK * man_ref + noise
    over_inv = np.flatnonzero(inv > inv_ref + scale_inv)
    over_man = np.flatnonzero(man > man_ref + scale_man)
    assert not len(over_inv), (task, threshold, over_inv[:5], inv[over_inv[:5]], inv_ref[over_inv[:5]])
    assert not len(over_man), (task, threshold, over_man[:5], man[over_man[:5]], man_ref[over_man[:5]])
    # The rows below the threshold are the true measure's (away from ties at the threshold).
    clear = np.abs(inv_ref - threshold) > 1e-9 * (threshold + 1e-12)
    assert np.array_equal((inv < threshold)[clear], (inv_ref < threshold)[clear])


def _walks(robot, rng: np.random.Generator, rows: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """Dense walks that stress the row projection: (configurations, rows keep)."""
    lo, hi = robot.lower, robot.upper
    qa, qb = robot.random_configurations(rng, 2)
    s = np.linspace(0.0, 1.0, rows)
    out = []
    # A straight move with a slow start and stop (rows bunched at the ends).
    smooth = s * s * s * (10 - 15 * s + 6 * s * s)
    out.append(qa + smooth[:, None] * (qb - qa))
    # Back and forth along the line, past its ends between anchors (projections clamped).
    wave = 0.5 - 0.6 * np.cos(7.0 * np.pi * s)
    out.append(np.clip(qa + wave[:, None] * (qb - qa), lo, hi))
    # Off the line: a sideways bulge and a wiggle of varying size.
    side = robot.random_configurations(rng, 1)[0] - qa
    amp = rng.uniform(0.0, 0.3)
    bulge = qa + s[:, None] * (qb - qa) + amp * np.sin(np.pi * s)[:, None] * side
    bulge += 1e-3 * rng.uniform() * np.sin(2 * np.pi * rng.uniform(5, 60) * s)[:, None] * rng.normal(size=robot.dof)
    out.append(np.clip(bulge, lo, hi))
    # A smooth random walk through the zero configuration (straight arms are often singular).
    jerk = rng.normal(0.0, 1.0, (rows, robot.dof))
    walk = np.cumsum(np.cumsum(np.cumsum(jerk, axis=0), axis=0), axis=0)
    walk = walk / max(float(np.max(np.abs(np.diff(walk, axis=0)))), 1e-300) * rng.uniform(5e-4, 4e-3)
    walk -= walk[rows // 2]
    out.append(np.clip(walk + np.clip(np.zeros(robot.dof), lo, hi), lo, hi))
    # A planned, timed trajectory sampled at 1 kHz (as plans are measured).
    waypoints = robot.random_configurations(rng, 3)
    trajectory = plan_trajectory(waypoints, JointLimits.from_robot(robot))
    t = np.unique(np.concatenate([trajectory.times(1000.0), trajectory.waypoint_times]))
    # At most 3 `rows` of it (the reference is a Python loop), the waypoints in it kept.
    cap = min(len(t), 3 * rows)
    planned = trajectory.positions(t[:cap])
    keep_planned = np.unique(np.concatenate([[0, cap - 1], np.searchsorted(t, trajectory.waypoint_times)]))
    keep_planned = keep_planned[keep_planned < cap]
    walks = [(w, np.array([0, rows // 3, rows - 1])) for w in out]
    walks.append((planned, keep_planned))
    return walks


def _fuzz(robot, seed: int, rows: int) -> None:
    rng = np.random.default_rng(seed)
    for q, keep in _walks(robot, rng, rows):
        for task in ("position", "pose"):
            reference = _reference(robot, q, task)
            default = inverse_condition_threshold(None, task)
            for threshold in (0.0, default, min(default * 5.0, 0.9)):
                _check_below(robot, q, task, threshold, keep, reference)


@pytest.mark.parametrize("name", ARMS)
def test_bounded_conditioning_never_exceeds_the_pinocchio_measure(name):
    _fuzz(get_robot(name), 11, 400)


@given(description=dh_descriptions(min_joints=3, max_joints=6), seed=st.integers(0, 2**32 - 1))
@property_settings(4)
def test_bounded_conditioning_never_exceeds_the_measure_on_random_dh_arms(description, seed):
    _fuzz(robot_from_description(description), seed, 300)


@pytest.mark.slow
@pytest.mark.parametrize("name", ARMS)
@pytest.mark.parametrize("seed", range(6))
def test_bounded_conditioning_never_exceeds_the_pinocchio_measure_long(name, seed):
    _fuzz(get_robot(name), 100 + seed, 2000)


@pytest.mark.slow
@given(description=dh_descriptions(min_joints=3, max_joints=6), seed=st.integers(0, 2**32 - 1))
@property_settings(60)
def test_bounded_conditioning_never_exceeds_the_measure_on_random_dh_arms_long(description, seed):
    _fuzz(robot_from_description(description), seed, 1500)


def _compiled_shifted_det():
    """The compiled shifted_det of planner.core.certificates alone (its C source cut out), or None."""
    import shutil
    import tempfile
    from pathlib import Path

    from planner.core import certificates

    compiler = shutil.which("cc") or shutil.which("gcc")
    if compiler is None or not COMPILED:
        return None
    source = certificates._SOURCE
    code = source[source.index("INLINE double int_power") : source.index("/* Cholesky factor L")]
    folder = Path(tempfile.mkdtemp())
    (folder / "sd.c").write_text(
        "#include <math.h>\n#include <float.h>\n#define INLINE static inline __attribute__((always_inline))\n"
        + code
        + "\ndouble sd(long k, double m2, double T, double P, double c) { return shifted_det(k, m2, T, P, c); }\n"
    )
    subprocess.run(
        [compiler, "-O2", "-shared", "-fPIC", "-o", str(folder / "sd.so"), str(folder / "sd.c"), "-lm"], check=True
    )
    lib = ctypes.CDLL(str(folder / "sd.so"))
    lib.sd.restype = ctypes.c_double
    lib.sd.argtypes = [ctypes.c_long] + [ctypes.c_double] * 4
    return lib.sd


def _shifted_det_cases(seed: int, count: int):
    """Random (k, M's eigenvalues, m2, T, P, c): m2 <= eigenvalues <= T, det M >= P, 0 <= c."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        k = int(rng.integers(1, 7))
        low = 10 ** rng.uniform(-8, 1)
        high = low * 10 ** rng.uniform(0, 6)
        mode = rng.integers(3)
        if mode == 0:
            mu = rng.uniform(low, high, k)
        elif mode == 1:
            mu = 10 ** rng.uniform(np.log10(low), np.log10(high), k)
        else:  # at the bounds, the vertices of the minimisation
            mu = np.where(rng.random(k) < 0.5, low, high)
        m2 = mu.min() * (1.0 - 0.5 * rng.random() * rng.integers(2))
        top = mu.max() * (1.0 + rng.random() * rng.integers(2))
        product = np.prod(mu) * (1.0 - rng.random() * rng.integers(2))
        c = m2 * rng.random() ** rng.integers(1, 4) * (1.0 if rng.random() < 0.95 else 1.5)
        yield k, mu, m2, top, product, c


def _check_shifted_det(seed: int, count: int) -> None:
    compiled = _compiled_shifted_det()
    rng = np.random.default_rng(seed + 1)
    for k, mu, m2, top, product, c in _shifted_det_cases(seed, count):
        basis = np.linalg.qr(rng.normal(size=(k, k)))[0]
        matrix = basis @ np.diag(mu) @ basis.T
        true = float(np.prod(mu - c)) if c < m2 else 0.0
        # The matrix itself: its det(M - c I) agrees with the eigenvalues' product.
        assert np.isclose(np.linalg.det(matrix - c * np.eye(k)), np.prod(mu - c), rtol=1e-6, atol=1e-12 * top**k)
        got = float(_shifted_det(k, np.array(m2), np.array(top), np.array(product), np.array(c)))
        assert got <= true * (1.0 + 1e-12), (k, mu, m2, top, product, c, got, true)
        # At least the bound it replaced: min(det) (1 - c / m2)^k (to rounding).
        old = max(product, m2**k) * max(1.0 - c / m2, 0.0) ** k if c < m2 else 0.0
        assert got >= old * (1.0 - 1e-9)
        if compiled is not None:
            assert np.isclose(compiled(k, m2, top, product, c), got, rtol=1e-13, atol=0.0)


def test_shifted_det_never_exceeds_det_m_minus_c():
    _check_shifted_det(0, 3000)


@pytest.mark.slow
def test_shifted_det_never_exceeds_det_m_minus_c_long():
    _check_shifted_det(1, 200000)
