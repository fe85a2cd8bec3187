"""The .csr route of the kinematic calibration end to end, stepped with a fake clock in one thread
(issue 25 item 2): ``calibrate program`` writes the proposed poses as a .csr in joint form; the arm of
a virtual G2 whose dimensions are not the model's (test/data/true_model_example.yaml: upper arm
+10 mm, forearm -5 mm, joint_2's zero 0.3 deg off) visits each taught point (here through protocol
v2's joint targets, as the pendant would move it); the driver's reported pose (what ``tool_pose``
publishes, off the DP wire) at each rest is recorded against the point's joints; the fit of those
pairs recovers the controller's dimensions within 0.2 mm / 0.02 deg."""
from __future__ import annotations

import math
import os


from vr_driver.csr import read_program
from vr_driver.csr.calibration import PairRecorder, RestDetector, model_errors, taught_points
from vr_driver.driver.motion.trajectories import TrajectoryGoal, validate
from vr_driver.kinematics.solver import Kinematics
from vr_driver.ros.calibration_recorder import Recording, main as calibrate

from panasonic_vr006l_support import kinematic_calibration as kc

from _world import World

TRUE_MODEL = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "data",
                          "true_model_example.yaml")
#: the calibration poses spread over the whole reach, beyond the driver's default box
REACH = {"x": [-2000.0, 2000.0], "y": [-2000.0, 2000.0], "z": [-2000.0, 2000.0]}


def move_to(world, target_rad):
    """A smooth joint move from where the arm is to ``target_rad`` (half the speed limits)."""
    q0 = world.status().joints
    vmax = world.kin.limits.velocity
    duration = max(0.5, max(abs(b - a) / (0.5 * v) for a, b, v in zip(q0, target_rad, vmax)) * 1.5)
    n = 20
    times, points = [], []
    for k in range(1, n + 1):
        u = k / n
        s = u * u * (3.0 - 2.0 * u)
        points.append(tuple(a + s * (b - a) for a, b in zip(q0, target_rad)))
        times.append(duration * u)
    names = world.core.joint_names
    goal = TrajectoryGoal(tuple(names), tuple(points), tuple(times))
    lim = world.kin.limits
    traj = validate(goal, names, q0, lim.lower, lim.upper, world.now)
    run = world.core.submit_trajectory(traj)
    world.run_until(lambda: run.done, duration + 10.0, "move to a taught point")
    assert run.success, run.failure()


def test_the_csr_route_recovers_the_controllers_dimensions(tmp_path):
    csr = str(tmp_path / "cal.csr")
    assert calibrate(["program", csr]) == 0
    points = taught_points(read_program(csr))
    assert len(points) == kc.DEFAULT_POSES

    world = World(None, {"workspace": REACH}, protocol="v2",
                  controller_kin=Kinematics.from_true_model(TRUE_MODEL))
    world.ready()
    said = []
    recording = Recording(PairRecorder(points, model_errors()), RestDetector(hold=1.0), say=said.append)
    seen = [0]

    def sample():
        for status in world.statuses[seen[0]:]:
            if status.pose is not None and status.record_time is not None:
                recording.pose(status.record_time, status.pose.as_tuple())
        seen[0] = len(world.statuses)

    for i, p in enumerate(points):
        move_to(world, tuple(math.radians(v) for v in p.joints_deg))
        sample()
        world.run_until(lambda: (sample(), len(recording.recorder.recorded) > i)[1], 3.0, "rest at %s" % p.name)
    assert recording.done.is_set() and recording.recorder.complete
    assert all("recorded" in line for line in said), said
    pairs_file = str(tmp_path / "pairs.yaml")
    recording.recorder.write(pairs_file, csr)

    result = kc.fit(kc.load_pairs(pairs_file))
    truth = kc.nominal_parameters(TRUE_MODEL)
    for name in ("upper_arm", "forearm", "shoulder_offset", "elbow_offset", "j5_to_flange"):
        assert abs(result.parameters[name] - truth[name]) * 1000.0 < 0.2, (name, result.summary())
    for name in kc.OFFSETS:
        assert abs(math.degrees(result.parameters[name] - truth[name])) < 0.02, (name, result.summary())
    # before: the model is 10 mm / 0.3 deg off; after: the residuals are the wire's rounding
    assert result.rms_mm < 0.05, result.summary()
