"""The 3-D view: the Scene API, the server it starts, and the scene as a person sees it in Chromium."""

from __future__ import annotations

import contextlib
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from browser import CHROMIUM, HeadlessChromium

import planner

from conftest import get_robot, needs_example_robot_data, run_cli

viser = pytest.importorskip("viser", reason="viser is not installed (pip install 'servo-arm-planner[view]')")

from planner.view import Scene  # noqa: E402
from planner.view.arm import ARM_COLOR  # noqa: E402

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "dh3_pick_and_place.yaml"
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="Chromium is not installed (Debian: apt-get install chromium); .ci/run installs it"
)


@pytest.fixture(scope="module")
def dh3_plan():
    request = planner.load_motion_request(EXAMPLE)
    return planner.plan_motion(get_robot("dh3"), request), request.labels


@pytest.fixture
def scene(dh3_plan):
    plan, labels = dh3_plan
    with Scene(get_robot("dh3"), plan, labels=labels, port=0) as s:
        yield s


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def wait_for_http(url: str, timeout: float = 30.0) -> str:
    deadline = time.monotonic() + timeout
    while True:
        try:
            with urllib.request.urlopen(url, timeout=2) as response:
                return response.read().decode("utf-8", "replace")
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)


# ---------------------------------------------------------------------------- the API, without a browser
def test_scene_serves_the_web_client_on_localhost(scene):
    assert scene.url == f"http://127.0.0.1:{scene.port}" and scene.port > 0
    page = wait_for_http(scene.url)
    assert "<html" in page.lower() and "<script" in page.lower()


def test_set_q_moves_the_arm_and_the_measures_follow(scene):
    robot = get_robot("dh3")
    q = np.array([0.3, 0.4, -0.9])
    scene.set_q(q)
    np.testing.assert_array_equal(scene.q, q)
    assert [s.value for s in scene._sliders] == pytest.approx(q.tolist())
    inverse, manipulability = scene.measures()
    assert inverse == pytest.approx(robot.inverse_condition_number(q, "position"))
    assert manipulability == pytest.approx(robot.manipulability(q, "position"))
    # The fully stretched arm is below the threshold: the panel says so in red.
    scene.set_q([0.0, 0.0, 0.0])
    assert scene.measures()[0] < scene.threshold
    assert "near a singularity" in scene._measure_html.content and "#d01010" in scene._measure_html.content


def test_sliders_span_the_joint_limits(scene):
    robot = get_robot("dh3")
    for slider, lo, hi in zip(scene._sliders, robot.lower, robot.upper):
        assert (slider.min, slider.max) == pytest.approx((lo, hi))


def test_bad_configurations_are_refused(scene):
    with pytest.raises(planner.JointLimitError):
        scene.set_q([0.0, 3.0, 0.0])
    with pytest.raises(planner.InvalidConfigurationError):
        scene.set_q([0.0, 0.1])


def test_target_shows_the_closed_form_branches_and_the_nlp_answer(scene):
    robot = get_robot("dh3")
    target = [0.10, 0.05, 0.05]
    result = scene.solve_target(target)
    assert result.success and result.method == "analytic" and len(result.solutions) >= 2
    np.testing.assert_allclose(robot.position(scene.q), target, atol=1e-9)
    assert len(scene._branch.options) == len(result.solutions)
    # Picking another branch shows it.
    other = next(k for k, s in enumerate(result.solutions) if s.within_limits and not np.array_equal(s.q, result.q))
    scene._branch.value = scene._branch.options[other]
    np.testing.assert_allclose(scene.q, result.solutions[other].q)
    nlp = scene.solve_target(target, method="nlp")
    assert nlp.success and nlp.method == "nlp"


def test_unreachable_target_shows_status_and_reason(scene):
    before = scene.q
    result = scene.solve_target([1.0, 0.0, 0.0])
    assert not result.success
    np.testing.assert_array_equal(scene.q, before)
    assert str(result.status) in scene._ik_html.content and "#d01010" in scene._ik_html.content


def test_plan_playback_and_scrubbing(scene, dh3_plan):
    plan, labels = dh3_plan
    scene.set_time(plan.waypoint_times[4])
    np.testing.assert_allclose(scene.q, plan.waypoints[4], atol=1e-9)
    assert scene.current_waypoint() == 4 and labels[4] in scene._plan_html.content
    scene.set_time(1e9)
    assert scene.time == pytest.approx(plan.trajectory.duration)
    scene.set_time(0.0)
    scene.play()
    assert scene.playing
    deadline = time.monotonic() + 10.0
    while scene.time == 0.0 and time.monotonic() < deadline:
        time.sleep(0.05)
    scene.pause()
    assert scene.time > 0.0 and not scene.playing


def test_bad_scene_input_is_refused(dh3_plan):
    plan, labels = dh3_plan
    with pytest.raises(planner.InvalidArgumentError, match="the plan has 3 joints; al5c has 5"):
        Scene(get_robot("al5c"), plan, port=0)
    with pytest.raises(planner.InvalidArgumentError, match="11 labels for 10 plan waypoints"):
        Scene(get_robot("dh3"), plan, labels=[*labels, "extra"], port=0)
    with pytest.raises(planner.InvalidArgumentError, match="port must be an integer in 0..65535"):
        Scene(get_robot("dh3"), port=70000)
    with pytest.raises(planner.InvalidArgumentError, match="unknown IK method 'best'"):
        Scene(get_robot("dh3"), ik_method="best")


def test_scene_refuses_what_is_not_a_plan_and_bad_times(scene):
    with pytest.raises(planner.InvalidArgumentError, match="plan must be a planner.MotionPlan, got dict"):
        Scene(get_robot("dh3"), {"waypoints": []}, port=0)
    for bad in (float("nan"), "1.0", None):
        with pytest.raises(planner.InvalidArgumentError, match="time must be a finite number"):
            scene.set_time(bad)


def test_scene_without_plan_refuses_playback():
    with Scene(get_robot("al5c"), port=0) as scene:
        with pytest.raises(planner.InvalidArgumentError, match="no plan"):
            scene.play()
        with pytest.raises(planner.InvalidArgumentError, match="no plan"):
            scene.set_time(1.0)


def test_a_plan_with_obstacles_shows_them():
    from planner.app.demo import al5c_request

    request, _ = al5c_request()
    plan = planner.plan_motion(get_robot("al5c"), planner.parse_motion_request(request))
    assert plan.scene is not None and plan.scene.obstacles
    with Scene(get_robot("al5c"), plan, port=0) as scene:
        scene.set_time(plan.trajectory.duration / 2)
        assert "waypoint" in scene._plan_html.content


def test_bundled_arms_are_drawn_with_link_geometry():
    with Scene(get_robot("dh3"), port=0) as scene:
        assert not scene.arm.uses_meshes
        # One cylinder per link between distinct joint origins, each as long as its link.
        points = get_robot("dh3").joint_positions(scene.q)
        lengths = sorted(h.scale[2] for _, h in scene.arm._links)
        distances = np.linalg.norm(np.diff(points, axis=0), axis=1)
        expected = sorted(distances[distances > 1e-6])
        assert lengths == pytest.approx(expected)


def test_unresolved_meshes_fall_back_to_link_geometry(tmp_path):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(
        """<robot name="meshy">
  <link name="base"><visual><geometry><mesh filename="package://nowhere/base.stl"/></geometry></visual></link>
  <link name="upper"/>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="upper"/><child link="tip"/><origin xyz="0.1 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
</robot>"""
    )
    with Scene(planner.load_robot(urdf), port=0) as scene:
        assert not scene.arm.uses_meshes


@needs_example_robot_data
def test_example_robot_data_arms_are_drawn_with_their_meshes():
    robot = planner.load_robot("ur5")
    with Scene(robot, port=0) as scene:
        assert scene.arm.uses_meshes
        scene.set_q([0.3, -1.0, 1.2, -0.5, 1.0, 0.0])
        np.testing.assert_allclose(scene.q, [0.3, -1.0, 1.2, -0.5, 1.0, 0.0])


def test_view_of_an_unknown_robot_is_a_one_line_error():
    result = run_cli("view", "nosuch", "--port", "0", timeout=60)
    assert result.returncode == 1
    assert result.stderr.startswith("planner view: error: unknown robot 'nosuch'")


def test_without_viser_the_command_names_the_extra():
    code = "import sys; sys.modules['viser'] = None; from planner.app.cli import main; sys.exit(main(sys.argv[1:]))"
    result = subprocess.run(
        [sys.executable, "-c", code, "view", "dh3", str(EXAMPLE)], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 1
    assert (
        result.stderr.strip() == "planner view: error: the 3-D view needs viser: pip install 'servo-arm-planner[view]'"
    )


def _sigint_default() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@contextlib.contextmanager
def serving(*args: str, timeout: float = 60.0):
    """Run a serving ``planner`` command until it says where it serves; Ctrl-C it on leaving.

    Yields the URL and a dict that gets ``code``, ``out`` and ``err`` once the command has stopped.
    """
    port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "planner", *args, "--port", str(port)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        # Ctrl-C as from a terminal, even where this test runs with SIGINT ignored (a shell
        # starts background jobs so, and the child would inherit it and never stop).
        preexec_fn=_sigint_default,
    )
    url = f"http://127.0.0.1:{port}"
    lines: list[str] = []
    reader = threading.Thread(target=lambda: lines.extend(process.stdout), daemon=True)
    reader.start()
    result: dict = {}
    try:
        deadline = time.monotonic() + timeout
        while not any(f"at {url}" in line for line in lines):
            assert process.poll() is None, process.stderr.read()
            assert time.monotonic() < deadline, f"no 'at {url}' within {timeout} s: {lines}"
            time.sleep(0.1)
        wait_for_http(url)
        yield url, result
    finally:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout=15)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()
        reader.join(timeout=5)
        result.update(code=process.returncode, out="".join(lines), err=process.stderr.read())
        process.stderr.close()


def serve_and_stop(*args: str) -> tuple[int, str, str]:
    """Run a serving ``planner`` command until it serves, then Ctrl-C it: exit code, stdout, stderr."""
    with serving(*args) as (_, result):
        pass
    return result["code"], result["out"], result["err"]


def test_plan_view_serves_the_plan_just_made():
    code, out, err = serve_and_stop("plan", "dh3", str(EXAMPLE), "--view")
    assert code == 0, err
    assert "SINGULAR" in out and "planner view: dh3 at" in out


def test_view_of_an_arm_alone():
    code, out, err = serve_and_stop("view", "al5c")
    assert code == 0, err


# ---------------------------------------------------------------------------- as a person sees it
def arm_pixels(pixels: np.ndarray) -> int:
    """Pixels of the arm's colour (orange, shaded) in the centre of the 3-D scene."""
    h, w, _ = pixels.shape
    centre = pixels[h // 4 : 3 * h // 4, w // 4 : 3 * w // 5]
    r, g, b = (centre[..., k] for k in range(3))
    target = np.array(ARM_COLOR)
    hue_like = (r > 120) & (r > g + 50) & (g > b + 20) & (b < 110)
    assert target[0] > target[1] > target[2]  # the test's colour rule assumes an orange arm
    return int(np.count_nonzero(hue_like))


@needs_chromium
def test_planner_view_shows_the_arm_in_chromium(tmp_path):
    with serving("view", "dh3", str(EXAMPLE)) as (url, result), HeadlessChromium() as browser:
        browser.open(url)
        pixels = browser.wait_for(lambda p: arm_pixels(p) > 300)
        browser.screenshot(tmp_path / "view.png")
    assert result["code"] == 0, result["err"]
    assert pixels.std() > 10, "the screenshot is blank"
    assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 200, "the screenshot is nearly blank"
    assert arm_pixels(pixels) > 300, "no arm-coloured pixels in the centre of the scene"


def changed_pixels(a: np.ndarray, b: np.ndarray) -> int:
    return int(np.count_nonzero(np.any(np.abs(a - b) > 30, axis=-1)))


@needs_chromium
def test_setting_a_joint_through_the_api_changes_the_screenshot(tmp_path):
    robot = get_robot("dh3")
    with Scene(robot, port=0) as scene, HeadlessChromium() as browser:
        scene.set_q([0.0, 0.9, -1.6])
        browser.open(scene.url)
        before = browser.wait_for(lambda p: arm_pixels(p) > 300)
        scene.set_q([1.2, -0.3, 0.5])
        after = browser.wait_for(lambda p: changed_pixels(before, p) > 1000)
        browser.screenshot(tmp_path / "after.png")
    assert arm_pixels(before) > 300 and arm_pixels(after) > 300
    assert changed_pixels(before, after) > 1000, "the view did not change when a joint was set"
