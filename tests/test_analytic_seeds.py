"""The seed documents' own IK cases, checked against correct geometry and Pinocchio FK."""

from __future__ import annotations

import math

import numpy as np
import pytest

from planner import Robot, Target, load_robot
from planner.export.calibration import angle_to_steps
from planner.ik.analytic import STATUS_BEYOND_MAX_REACH, STATUS_INSIDE_MIN_REACH, STATUS_SOLVED, closed_form_solver
from planner.model.catalog import bundled_urdf_path

TOL_POS = 1e-9


def wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def fk_position(robot, q):
    return robot.fk(q)[:3, 3]


@pytest.fixture(scope="module")
def dh3():
    robot = load_robot("dh3")
    return robot, closed_form_solver(robot)


@pytest.fixture(scope="module")
def al5c():
    robot = load_robot("al5c")
    return robot, closed_form_solver(robot)


@pytest.fixture(scope="module")
def three_joint():
    robot = load_robot("three_joint")
    return robot, closed_form_solver(robot)


@pytest.fixture(scope="module")
def shelley():
    robot = load_robot("shelley")
    return robot, closed_form_solver(robot)


# ---------------------------------------------------------------------------- 004: Sumadsad's DH arm
def seed004_fk_cm(q):
    """Sumadsad's (2020) closed-form FK [cm]: x = C1 (6 C2 + 11 C23), ..., S23 = sin(theta2 - theta3)."""
    t1, t2, t3 = q
    reach = 6 * math.cos(t2) + 11 * math.cos(t2 - t3)
    return np.array([math.cos(t1) * reach, math.sin(t1) * reach, 6 * math.sin(t2) + 11 * math.sin(t2 - t3) + 3])


def test_004_the_arm_matches_the_seed_forward_model(dh3):
    robot, _ = dh3
    for q in robot.random_configurations(np.random.default_rng(4), 10):
        np.testing.assert_allclose(fk_position(robot, q) * 100, seed004_fk_cm(q), atol=1e-10)


def test_004_its_45_90_90_check(dh3):
    robot, solver = dh3
    q = np.radians([45.0, 90.0, 90.0])
    target = Target(fk_position(robot, q))
    np.testing.assert_allclose(target.position * 100, [11 / math.sqrt(2), 11 / math.sqrt(2), 9.0], atol=1e-12)
    res = solver.solve(target)
    assert res.status == STATUS_SOLVED and len(res.solutions) == 4
    back = [s for s in res.solutions if np.allclose(s.q, q, atol=1e-12)]
    assert len(back) == 1 and back[0].within_limits and back[0].branch == "front/elbow-up"
    for sol in res.solutions:
        np.testing.assert_allclose(seed004_fk_cm(sol.q), target.position * 100, atol=1e-10)


STATE_TABLE_CM = [(17, 0, 3), (14, 0, -4), (11, 0, 9), (7.7, 7.7, 9), (0, 11, 9), (0, 17, 3), (0, 14, -4)]


@pytest.mark.parametrize("position_cm", STATE_TABLE_CM)
def test_004_state_table_positions(dh3, position_cm):
    robot, solver = dh3
    p = np.array(position_cm, dtype=float) / 100
    res = solver.solve(Target(p))
    assert res.status == STATUS_SOLVED
    stretched = math.hypot(math.hypot(p[0], p[1]), p[2] - 0.03) == pytest.approx(0.17, abs=1e-12)
    assert len(res.solutions) == (2 if stretched else 4)
    assert res.singular == stretched
    # The seed's inverse: theta1 = atan2(py, px) (front) and C3 from the squared sum.
    c3 = ((p[0] ** 2 + p[1] ** 2 + (p[2] - 0.03) ** 2) * 1e4 - 157) / 132
    for sol in res.solutions:
        assert np.linalg.norm(fk_position(robot, sol.q) - p) < TOL_POS
        np.testing.assert_allclose(seed004_fk_cm(sol.q), p * 100, atol=1e-9)
        assert math.cos(sol.q[2]) == pytest.approx(min(c3, 1.0), abs=1e-9)
        if sol.branch.startswith("front"):
            assert wrap(sol.q[0] - math.atan2(p[1], p[0])) == pytest.approx(0.0, abs=1e-12)
        else:
            assert abs(wrap(sol.q[0] - math.atan2(p[1], p[0]))) == pytest.approx(math.pi, abs=1e-12)


# ---------------------------------------------------------------------------- 001: AL5C approach modes
L1, L2, L3, H0 = 0.14605, 0.187325, 0.100, 0.06731


def corrected_seed001(d_a, h_a):
    """Clothier and Shang's (2010) shoulder/elbow by correct geometry: L = sqrt(DA^2 + HA^2), phi1 = atan2(HA, DA)."""
    length = math.hypot(d_a, h_a)
    phi1 = math.atan2(h_a, d_a)
    shoulder = phi1 + math.acos((L1**2 + length**2 - L2**2) / (2 * L1 * length))  # elbow up
    inner = math.acos((L1**2 + L2**2 - length**2) / (2 * L1 * L2))  # angle between humerus and ulna
    return shoulder, -(math.pi - inner)  # our elbow: 0 = straight, negative = folded down


def garbled_seed001(d_a, h_a):
    """Equations (2)-(3) as printed in Clothier and Shang (2010) (the typos kept), for contrast only."""
    length = d_a / h_a
    phi1 = math.atan(h_a / d_a)
    with np.errstate(invalid="ignore"):
        theta1 = np.arccos(L1**2 + L2**2 - L3**2) / (2 * L1 * length) + phi1
        theta2 = np.arccos(L1**2 - L2**2 + L3**2) / (2 * L1 * L2) - math.pi / 2
    return float(theta1), float(theta2)


@pytest.mark.parametrize(("mode", "pitch"), [("parallel", 0.0), ("straight_down", -math.pi / 2)])
@pytest.mark.parametrize(("d", "h", "yaw"), [(0.30, 0.10, 0.0), (0.25, 0.02, 0.5), (0.20, 0.15, -0.9)])
def test_001_approach_modes(al5c, mode, pitch, d, h, yaw):
    robot, solver = al5c
    target = np.array([d * math.cos(yaw), d * math.sin(yaw), h])
    res = solver.solve(Target(target, pitch=pitch))
    sol = next(s for s in res.solutions if s.branch == "front/elbow-up")
    # The seed's translated points: (D - L3, H - h0) parallel, (D, H - h0 + L3) straight down.
    d_a, h_a = (d - L3, h - H0) if mode == "parallel" else (d, h - H0 + L3)
    shoulder, elbow = corrected_seed001(d_a, h_a)
    assert sol.q[0] == pytest.approx(yaw, abs=1e-12)
    assert sol.q[1] == pytest.approx(shoulder, abs=1e-12)
    assert sol.q[2] == pytest.approx(elbow, abs=1e-12)
    # The wrist takes up the rest: the pitch joints sum to the approach pitch.
    assert sol.q[1] + sol.q[2] + sol.q[3] == pytest.approx(pitch, abs=1e-12)
    assert np.linalg.norm(fk_position(robot, sol.q) - target) < TOL_POS
    approach = robot.fk(sol.q)[:3, :3] @ robot.approach_axis
    np.testing.assert_allclose(
        approach, [math.cos(pitch) * math.cos(yaw), math.cos(pitch) * math.sin(yaw), math.sin(pitch)], atol=1e-12
    )
    # The garbled equations as printed would put the arm elsewhere (or give no number at all).
    g1, g2 = garbled_seed001(d_a, h_a)
    if math.isfinite(g1) and math.isfinite(g2):
        wrist = np.array([L1 * math.cos(g1) + L2 * math.cos(g1 + g2), L1 * math.sin(g1) + L2 * math.sin(g1 + g2)])
        assert np.linalg.norm(wrist - [d_a, h_a]) > 0.01
    assert abs(g1 - shoulder) > 0.01 or not math.isfinite(g1)


# ---------------------------------------------------------------------------- 002: three-joint coursework
D2, D3, D4 = 4.0, 4.0, 2.0


def seed002(px, py, pz, alpha, sign):
    """Vaishnav's closed form (section 4), elbow sign `sign` = +1 or -1."""
    t1 = math.atan2(py, px)
    p1 = px * math.cos(t1) + py * math.sin(t1) - D4 * math.cos(alpha)
    p2 = pz - D4 * math.sin(alpha)
    c3 = (p1 * p1 + p2 * p2 - D2 * D2 - D3 * D3) / (2 * D2 * D3)
    t3 = math.atan2(sign * math.sqrt(1 - c3 * c3), c3)
    k1, k2 = D3 * c3 + D2, D3 * math.sin(t3)
    t2 = math.atan2(k1 * p2 - k2 * p1, k1 * p1 + k2 * p2)
    return np.array([t1, t2, t3, alpha - t2 - t3])


def test_002_closed_form_matches_the_front_branches(three_joint):
    robot, solver = three_joint
    rng = np.random.default_rng(2)
    checked = 0
    for q in robot.random_configurations(rng, 40):
        p = fk_position(robot, q)
        radial = p[:2] / np.linalg.norm(p[:2])
        approach = robot.fk(q)[:3, :3] @ robot.approach_axis
        alpha = math.atan2(approach[2], approach[:2] @ radial)
        res = solver.solve(Target(p, pitch=alpha))
        fronts = {s.branch: s.q for s in res.solutions if s.branch.startswith("front")}
        for branch, sign in (("front/elbow-up", -1), ("front/elbow-down", +1)):
            if branch in fronts:
                np.testing.assert_allclose(wrap(fronts[branch] - seed002(*p, alpha, sign)), 0.0, atol=1e-9)
                checked += 1
        backs = [s for s in res.solutions if s.branch.startswith("back")]
        for s in backs:  # theta1 + pi: reaching back over the base
            assert abs(wrap(s.q[0] - math.atan2(p[1], p[0]))) == pytest.approx(math.pi, abs=1e-12)
    assert checked > 40


@pytest.mark.parametrize("pitch", [math.pi / 2, None])
def test_002_straight_up_degeneracy(three_joint, pitch):
    robot, solver = three_joint
    target = Target([0.0, 0.0, D2 + D3 + D4], pitch=pitch)
    for q_current, yaw in ((None, 0.0), ([0.7, 1.0, 0.2, -0.1], 0.7)):
        res = solver.solve(target, q_current=q_current)
        assert res.status == STATUS_SOLVED and res.singular
        assert len(res.solutions) == 1
        sol = res.solutions[0]
        # theta1 free (the current yaw is kept), theta2 = 90 deg, theta3 = theta4 = 0.
        np.testing.assert_allclose(sol.q, [yaw, math.pi / 2, 0.0, 0.0], atol=1e-7)
        assert sol.singular and np.all(np.isfinite(sol.q))
        assert np.linalg.norm(fk_position(robot, sol.q) - target.position) < TOL_POS


def test_002_workspace_boundary(three_joint):
    _, solver = three_joint
    rng = np.random.default_rng(0)
    for direction in rng.normal(size=(10, 3)):
        direction /= np.linalg.norm(direction)
        res = solver.solve(Target(direction * 10.000001))
        assert res.status == STATUS_BEYOND_MAX_REACH and res.solutions == ()
        assert "beyond the 10 m" in res.reason
    # The seed checks each coordinate against 10; (8, 8, 0) passes that but lies 11.3 m out.
    assert solver.solve(Target([8.0, 8.0, 0.0])).status == STATUS_BEYOND_MAX_REACH
    assert solver.solve(Target([9.999, 0.0, 0.0])).status == STATUS_SOLVED


# ---------------------------------------------------------------------------- 000: Shelley
def shelley_variant(claw_offset: float) -> Robot:
    text = bundled_urdf_path("shelley").read_text()
    return Robot(text.replace('xyz="0.08 0.01 0"', f'xyz="0.08 {claw_offset!r} 0"'), tip="claw")


def seed000_minreach(r1, r2, servo2_max):
    """Materick and Shapiro's (1997) MINREACH (EQ 3-8)."""
    theta = math.pi - servo2_max
    return math.sqrt((r2 * math.sin(theta)) ** 2 + (r1 - r2 * math.cos(theta)) ** 2)


def test_000_min_reach_formula(shelley):
    free = closed_form_solver(shelley_variant(0.0))
    assert free.reach[0] == pytest.approx(seed000_minreach(0.10, 0.08, math.radians(92.5)), abs=1e-12)
    assert free.reach[1] == pytest.approx(0.18, abs=1e-12)
    # With the claw offset the effective second link is longer and already turned by the offset.
    _, solver = shelley
    r2 = math.hypot(0.08, 0.01)
    expected = seed000_minreach(0.10, r2, math.radians(92.5) + math.atan2(0.01, 0.08))
    assert solver.reach[0] == pytest.approx(expected, abs=1e-12)
    inside = solver.solve(Target([expected - 1e-4, 0.0, 0.0]))
    assert inside.status == STATUS_INSIDE_MIN_REACH and not any(s.within_limits for s in inside.solutions)
    assert solver.solve(Target([expected + 1e-4, 0.0, 0.0])).status == STATUS_SOLVED


@pytest.mark.parametrize("target", [[0.15, 0.0, 0.0], [0.0, 0.15, 0.0], [-0.13, 0.0, 0.0], [0.12, -0.05, 0.0]])
def test_000_targets_on_an_axis(shelley, target):
    # The seed's k = 0 case divides by zero in EQ 9; the law of cosines has no such case.
    robot, solver = shelley
    res = solver.solve(Target(target))
    assert len(res.solutions) == 2
    for sol in res.solutions:
        assert np.linalg.norm(fk_position(robot, sol.q) - target) < TOL_POS
    free = closed_form_solver(shelley_variant(0.0))
    if target[1] == 0.0 and target[0] > 0:  # claw-free: the two intersections mirror in x
        a, b = free.solve(Target(target)).solutions
        assert a.q[0] == pytest.approx(-b.q[0], abs=1e-12) and a.q[1] == pytest.approx(-b.q[1], abs=1e-12)


def test_000_target_at_the_base(shelley):
    _, solver = shelley
    res = solver.solve(Target([0.0, 0.0, 0.0]))
    assert res.status == STATUS_INSIDE_MIN_REACH and res.solutions == ()
    assert "0 m from the base axis" in res.reason


def test_000_claw_offset_compensated(shelley):
    robot, solver = shelley
    r2 = math.hypot(0.08, 0.01)
    straight = closed_form_solver(shelley_variant(0.0))
    correct = math.asin(0.01 / r2)  # the seed's CORRECT, measured on the hypotenuse
    for target in ([0.15, 0.03, 0.0], [0.05, 0.14, 0.0]):
        # An arm whose r2 is the claw's hypotenuse reaches the same point; shelley's servo 2 differs
        # from it by exactly the claw angle.
        longer = Robot(
            bundled_urdf_path("shelley").read_text().replace('xyz="0.08 0.01 0"', f'xyz="{r2!r} 0 0"'), tip="claw"
        )
        ref = closed_form_solver(longer).solve(Target(target))
        res = solver.solve(Target(target))
        for a, b in zip(res.solutions, ref.solutions):
            assert a.q[0] == pytest.approx(b.q[0], abs=1e-12)
            assert a.q[1] == pytest.approx(b.q[1] - correct, abs=1e-12)
            assert np.linalg.norm(fk_position(robot, a.q) - target) < TOL_POS
        assert straight.solve(Target(target)).solutions[0].q[1] != pytest.approx(res.solutions[0].q[1], abs=1e-3)


def test_000_over_rotation_takes_the_other_intersection(shelley):
    # Servo 1 of the first intersection would turn past 92.5 deg; the other one is used.
    _, solver = shelley
    res = solver.solve(Target([0.0, 0.15, 0.0]))
    assert res.status == STATUS_SOLVED
    assert [s.within_limits for s in res.solutions] == [False, True]
    assert res.best.branch == "elbow-right"


def seed_program_arm() -> Robot:
    """The arm of Materick and Shapiro's (1997) program: r1 = 10, r2 = 13, servos +-90 deg, zero along +y."""
    return Robot(
        '<robot name="tttarms"><link name="base"/><link name="l1"/><link name="l2"/><link name="ee"/>'
        '<joint name="servo1" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0"/>'
        f'<axis xyz="0 0 1"/><limit lower="{-math.pi / 2!r}" upper="{math.pi / 2!r}" effort="1" velocity="1"/></joint>'
        '<joint name="servo2" type="revolute"><parent link="l1"/><child link="l2"/><origin xyz="0 10 0"/>'
        f'<axis xyz="0 0 1"/><limit lower="{-math.pi / 2!r}" upper="{math.pi / 2!r}" effort="1" velocity="1"/></joint>'
        '<joint name="ee_fixed" type="fixed"><parent link="l2"/><child link="ee"/><origin xyz="0 13 0"/></joint>'
        "</robot>",
        tip="ee",
    )


def test_000_sample_runs_of_the_seed_program():
    robot = seed_program_arm()
    solver = closed_form_solver(robot)
    assert solver.reach[0] == pytest.approx(seed000_minreach(10, 13, math.pi / 2), abs=1e-12)
    runs = [  # (target, seed's intersection (elbow), seed's |servo 1| angle, |steps|)
        ((0.0, 23.0), (0.0, 10.0), 0.0, 0),
        ((23.0, 0.0), (10.0, 0.0), 1.570796, 1400),
        ((-7.0, 16.0), (-9.462180, 3.235296), 1.241339, 1106),
    ]
    for target, elbow, angle, steps in runs:
        res = solver.solve(Target([*target, 0.0]))
        assert res.status == STATUS_SOLVED
        elbows = [robot.fk(s.q, frame="servo2")[:2, 3] for s in res.solutions]
        k = int(np.argmin([np.linalg.norm(e - elbow) for e in elbows]))
        np.testing.assert_allclose(elbows[k], elbow, atol=5e-6)
        sol = res.solutions[k]
        assert abs(sol.q[0]) == pytest.approx(angle, abs=5e-6)
        assert abs(angle_to_steps(sol.q[0], math.pi / 2, 1400)) == steps
        assert sol.singular == (math.hypot(*target) == 23.0)
