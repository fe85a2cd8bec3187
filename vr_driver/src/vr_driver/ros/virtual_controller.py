"""ROS node `virtual_controller`: the thin ROS edge of :class:`vr_driver.controller.virtual_controller.VirtualController`.

Private parameters (validated by ``controller.options.SimOptions``; defaults in brackets):
``~pty_link`` [""] create a pty pair and symlink its device end here (``auto``: this launch's own
link, ``controller.pty_link.auto_pty_link``; a link another live controller holds is refused); ``~device`` [""] serve this
existing device instead; ``~addr`` [4]; ``~baud`` [19200]; ``~speed_factor`` [1.0];
``~initial_pose`` [[1120, 0, 725, 0, 45, 0]] (mm, deg); ``~loop_period`` [0.01] s;
``~byte_order`` ["little"]; ``~log_file`` [""] (JSON lines of the handled targets);
``~brake_time`` [0.3] s of robot time a stop takes from path speed to rest (0: halts at once);
``~protocol`` ["v1"] the robot program: v1 (14-byte handshake), v2 (streamed joint targets) or v3
(streamed Cartesian targets); ``~interpreter_lookahead`` [1], ``~ring_size`` (v3);
``~ramp_time`` [unset: from the model's joint limits, max velocity / acceleration, 0.1 s] s of robot
time the v2 / v3 arm takes from rest to full speed (e.g. 0.5: an older controller; > 0);
``~configuration`` ["previous_target"] (v1, v3) the joint solution the G2 takes for a Cartesian
target: nearest the previous target's joints or ``current_joints`` (doc/controller_program.md §7);
``~true_model`` [""] a YAML of the simulated robot's own dimensions and joint zero offsets
(panasonic_vr006l_support.true_model; empty: the model's): the arm and the v3 program compute with
it while the driver keeps the model, as with a real robot that differs from the model.
The assumptions about the real G2 (``controller.options.ASSUMPTIONS``, doc/controller_program.md
§10.9; the defaults keep the model the stack is tested against): ``~data_exchange_bit`` [true];
``~speed_scale`` [1.0] (v2, v3: MOVEP's speed unit, real speed = commanded x scale);
``~loop_blocks_during_move`` [false] (a MOVE blocks the program loop, the feedback frozen);
``~blend_across_input_read`` [true] (v2, v3: false: an exact stop at every point);
``~loop_jitter`` [0.0] s, ``~loop_jitter_seed`` [0] (the loop period's spread); ``~send_ahead``
["accepted"] (v3; or "refused"); ``~unreachable`` ["skip"] (or "alarm_halt"); ``~ramp_shape``
["linear"] (v2, v3; or "s_curve"); ``~accelerations`` [unset] (v2, v3: 6 numbers, rad/s^2, a list
or a string; not with ``~ramp_time``). A bad value is refused at start (exit status 2).

Sets ``~device_path`` to the device a master must open. Services (std_srvs/SetBool):
``~set_estop`` (True presses the e-stop), ``~set_drives_powered`` (False switches the drives off),
``~set_error`` (True sets a controller error). Publishes ``~executed`` (std_msgs/String, latched):
one JSON object per handled target (``controller.arm.LogEntry.to_json``: seq, move_type, target, outcome
executed / rejected / via_stored, reason, times, final_pose; v2: ``controller.stream_arm.StreamLogEntry``).
``~true_joints`` (sensor_msgs/JointState, 50 Hz; a simulation-only diagnostic): the simulated arm's
joints [rad] in the TRUE robot's angles (``VirtualController.true_joints``: the controller's plus the
true model's zero offsets, from the model's zero pose; without ``~true_model`` the controller's),
names joint_1 .. joint_6, stamped with the ROS time the arm was there (its program loop's step:
``VirtualController.true_joints_sample``, not the later moment they were read, which a busy machine
delays by tens of ms) -- where the arm really is, which joint_states (the driver's model, v1 / v3:
its IK of the reported pose) may not show.

Exit status: 0 on shutdown, 2 bad parameter, 3 device problem, 1 internal error.
"""
from __future__ import annotations

from typing import Any, Dict, Mapping, Tuple

import rospy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool, SetBoolResponse

from ..controller.options import PARAM_NAMES, SimOptions
from ..controller.pty_link import AUTO_LINK
from ..controller.simulator import EXIT_OK
from ..controller.virtual_controller import VirtualController
from .support import (init_node, open_device, own_link, route_to_rosout, stop_on_signals, virtual_hardware_priority,
                      watch_simulator)
from ..controller.arm import LogEntry

#: parameters the node writes itself (not options)
_OWN_PARAMS = ("device_path", "rt_priority")

#: Hz of ~true_joints
TRUE_JOINTS_RATE = 50.0
TRUE_JOINT_NAMES = tuple("joint_%d" % i for i in range(1, 7))

_SERVICES = (("set_estop", "estop"), ("set_drives_powered", "drives_powered"), ("set_error", "error"))


def split_params(params: Mapping[str, Any]) -> Tuple[Dict[str, Any], Tuple[str, ...]]:
    """(the option parameters, the names of unknown ones) from ``rospy.get_param('~')``."""
    known = {k: v for k, v in params.items() if k in PARAM_NAMES}
    unknown = tuple(sorted(k for k in params if k not in PARAM_NAMES and k not in _OWN_PARAMS))
    return known, unknown


def main() -> int:
    stop = stop_on_signals()
    init_node("virtual_controller", disable_signals=True)
    route_to_rosout("vr_driver", "pyprofibus_vendor")
    params, unknown = split_params(rospy.get_param("~", {}) or {})
    if unknown:
        rospy.logwarn("virtual_controller: ignoring unknown parameter(s) %s", ", ".join(unknown))

    def read_options() -> SimOptions:
        if params.get("pty_link") == AUTO_LINK:
            params["pty_link"] = own_link(AUTO_LINK, "g2")
        return SimOptions.from_mapping(params)
    options, status = open_device("virtual_controller", read_options)
    if options is None:
        return status
    controller, status = open_device(
        "virtual_controller", lambda: VirtualController(options.device, **options.controller_kwargs()))
    if controller is None:
        return status

    executed = rospy.Publisher("~executed", String, queue_size=100, latch=True)

    def publish(entry: LogEntry) -> None:
        executed.publish(String(data=entry.to_json()))

    def handler(fault: str):
        def handle(request: Any) -> Any:
            ok, message = controller.set_fault(fault, bool(request.data))
            return SetBoolResponse(success=ok, message=message)
        return handle

    controller.log.add_listener(publish)
    true_joints = rospy.Publisher("~true_joints", JointState, queue_size=10)

    def publish_true_joints() -> None:
        joints, age = controller.true_joints_sample()
        msg = JointState(name=list(TRUE_JOINT_NAMES), position=list(joints))
        msg.header.stamp = rospy.Time.now() - rospy.Duration.from_sec(age)     # when the arm was there
        true_joints.publish(msg)
    services = [rospy.Service("~" + name, SetBool, handler(fault)) for name, fault in _SERVICES]
    rospy.on_shutdown(controller.request_stop)     # e.g. rosnode kill; the real stop is below
    controller.start()
    virtual_hardware_priority("virtual_controller")      # once it runs: its set-up at normal priority
    rospy.set_param("~device_path", controller.device_path)
    rospy.loginfo("virtual_controller: DP slave %d on %s%s, speed x%g", options.address, controller.device_path,
                  " (linked at %s)" % controller.symlink if controller.symlink else "", options.speed_factor)
    try:
        status = watch_simulator(controller, "virtual_controller", stop, TRUE_JOINTS_RATE,
                                 each=publish_true_joints)
    finally:
        for service in services:
            service.shutdown()
        controller.stop()
    rospy.signal_shutdown("virtual controller stopped" if status == EXIT_OK else "virtual controller failed")
    return status
