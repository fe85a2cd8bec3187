"""joint_command (joint targets streamed on the fly) stepped with a fake clock, in one thread: the
driver core's JointCommander and the StreamSequencer's live stream, our DP master, the in-memory
link and the virtual controller's v2 / v3 program and streaming arm (_world.World). Commands are
issued at given world times between the world's ticks, as a publisher would.

What is shown: a sine on J1 commanded at 50 Hz is followed (v2 and v3); a command replaces the one
not yet on the wire; when the commands stop the arm rests at the last accepted target within one
bus cycle plus joint_command_timeout and the stream ends; every bad command is refused with its rule
and changes nothing; v1 refuses the topic; a running move refuses it; stop_motion and a trajectory
take over from it."""
from __future__ import annotations

import math

import pytest

from vr_driver.driver import JobPhase
from vr_driver.driver.checks.joint_command import JointCommandRefused
from vr_driver.params import DriverParams, ParamError
from vr_driver.poses import ControllerPose
from vr_driver.driver.motion.jobs import MoveRequest, StreamPoint
from vr_driver.poses import MoveType

from _world import World
from test_streaming_stepped import trajectory

DEG = math.pi / 180.0
NAMES = tuple("joint_%d" % i for i in range(1, 7))
FAST_BUS = {"cycle_rate": 100.0, "baud": 187500, "joint_states_rate": 100.0}


def make(kin, protocol="v2", **params):
    w = World(kin, dict(FAST_BUS, **params), protocol=protocol)
    w.ready()
    return w


def run_to(world, t):
    while world.now < t:
        world.tick()


def sine(q0, amp=5.0 * DEG, freq=0.5):
    return lambda t: tuple(q0[0] + amp * math.sin(2 * math.pi * freq * t) if i == 0 else v
                           for i, v in enumerate(q0))


def stream(world, f, rate=50.0, duration=2.0, samples=None):
    """Command f(t) at ``rate`` for ``duration`` (t from the first command); every command must be
    accepted. ``samples`` collects (t, arm joints) at every tick. Returns (t0, times, commands, job)."""
    t0 = world.now
    times, commands, job = [], [], None
    k = 0
    while True:
        t = t0 + k / rate
        if t > t0 + duration + 1e-9:
            break
        while world.now < t:
            world.tick()
            if samples is not None:
                samples.append((world.now, tuple(world.arm.joints)))
        q = f(world.now - t0)
        times.append(world.now)
        job = world.core.joint_command(NAMES, q)
        commands.append(q)
        k += 1
    return t0, times, commands, job


def wire_seqs(world):
    return [e.seq for e in world.log.entries()]


@pytest.mark.parametrize("protocol", ["v2", "v3"])
def test_a_sine_at_50_hz_is_followed_and_ends_at_rest_at_the_last_target(kin, protocol):
    world = make(kin, protocol)
    q0 = tuple(world.arm.joints)
    samples = []
    t0, times, commands, job = stream(world, sine(q0), duration=2.0, samples=samples)
    t_last = times[-1]
    assert job.live and not job.done
    # the arm followed: compared with the command shifted by the lag that fits best
    moving = [(t, q) for t, q in samples if t >= t0 + 0.3]

    def err(lag):
        return max(abs(q[0] - (q0[0] + 5.0 * DEG * math.sin(math.pi * (t - lag - t0)))) for t, q in moving)
    lags = [i * 0.005 for i in range(0, 41)]
    lag = min(lags, key=err)
    assert err(lag) <= 0.2 * DEG, "%.3f deg off at the best lag %.3f s" % (err(lag) / DEG, lag)
    # the arm runs one command behind (it blends only into a target it has): two command periods,
    # plus the bus cycle and the program loop on the way there and the record on the way back
    assert lag <= 2 * 0.02 + 3 * world.bus_period, lag
    # (the other joints stay: within the wire's rounding, v3 the controller's IK of the rounded pose)
    still = 0.001 * DEG if protocol == "v2" else world.core.wire.target_error
    assert all(max(abs(a - b) for a, b in zip(q[1:], q0[1:])) <= still for _t, q in samples)
    print("lag %.3f s, %.4f deg off" % (lag, err(lag) / DEG))
    # the end: within one bus cycle + joint_command_timeout the stream is over and the arm at rest
    # exactly at the last accepted target (v3: within what the wire's rounding costs)
    deadline = t_last + world.params.joint_command_timeout + world.bus_period
    world.run_until(lambda: job.done, deadline - world.now + 1e-9, "the stream's end")
    assert world.now <= deadline + 1e-9
    assert job.result.success, job.result.reason
    tol = 0.001 * DEG if protocol == "v2" else world.core.wire.target_error
    assert max(abs(a - b) for a, b in zip(world.arm.joints, commands[-1])) <= tol
    # every point on the wire once, in order
    seqs = wire_seqs(world)
    assert seqs == job.seqs and len(set(seqs)) == len(seqs) == len(job.points)
    assert world.core.joint_commander.counters().refused_total == 0
    assert world.core.joint_commander.counters().accepted == len(commands)


def test_a_new_command_replaces_the_one_not_yet_on_the_wire(kin):
    """200 commands/s on a 20 Hz bus: each bus cycle carries only the newest; the controller gets
    far fewer targets than commands, and the last one exactly."""
    world = make(kin, "v2", cycle_rate=20.0)
    q0 = tuple(world.arm.joints)
    _t0, _times, commands, job = stream(world, sine(q0, amp=2.0 * DEG), rate=200.0, duration=1.0)
    world.run_until(lambda: job.done, 1.0, "the stream's end")
    assert job.result.success, job.result.reason
    assert job.replaced > 0
    assert len(job.points) + job.replaced == len(commands)
    assert len(job.points) < len(commands) / 2
    assert wire_seqs(world) == job.seqs
    assert max(abs(a - b) for a, b in zip(world.arm.joints, commands[-1])) <= 0.001 * DEG
    assert job.points[-1].joints == commands[-1]


def test_commands_after_the_timeout_start_a_new_stream(kin):
    world = make(kin, "v2")
    q = list(world.arm.joints)
    q[0] += 0.01
    first = world.core.joint_command(NAMES, q)
    timeout = world.params.joint_command_timeout
    run_to(world, world.now + timeout / 2)
    assert world.core.joint_command(NAMES, q) is first          # within the timeout: the same
    t = world.now
    world.run_until(lambda: first.done, timeout + world.bus_period + 1e-9, "the first stream's end")
    assert world.now - t <= timeout + world.bus_period + 1e-9
    assert first.result.success
    q[0] += 0.01
    second = world.core.joint_command(NAMES, q)
    assert second is not first and second.live
    world.run_until(lambda: second.done, 1.0)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, q)) <= 0.001 * DEG
    assert world.core.joint_commander.counters().streams == 2


def test_names_in_another_order_are_reordered(kin):
    world = make(kin, "v2")
    q = list(world.arm.joints)
    q[2] += 0.02
    order = [5, 2, 0, 4, 1, 3]
    job = world.core.joint_command([NAMES[i] for i in order], [q[i] for i in order])
    world.run_until(lambda: job.done, 1.0)
    assert max(abs(a - b) for a, b in zip(world.arm.joints, q)) <= 0.001 * DEG


def refused(world, kind, names, positions, time_from_start=0.0, words=()):
    before_log = len(world.log.entries())
    before = tuple(world.arm.joints)
    n = world.core.joint_commander.counters().refused[kind]
    with pytest.raises(JointCommandRefused) as info:
        world.core.joint_command(names, positions, time_from_start)
    assert info.value.kind == kind
    text = str(info.value)
    assert "nothing was sent" in text
    for word in words:
        assert word in text, text
    world.run_for(0.3)
    assert len(world.log.entries()) == before_log              # nothing reached the controller
    assert tuple(world.arm.joints) == before                    # the arm stayed put
    assert world.core.joint_commander.counters().refused[kind] == n + 1
    return text


@pytest.mark.parametrize("protocol", ["v2", "v3"])
def test_bad_commands_are_refused_and_change_nothing(kin, protocol):
    world = make(kin, protocol, workspace={"x": [100, 1400], "y": [-100, 100], "z": [0, 1400]})
    q = list(world.arm.joints)
    nan = list(q)
    nan[3] = float("nan")
    refused(world, "not_finite", NAMES, nan, words=("joint_4",))
    inf = list(q)
    inf[1] = float("inf")
    refused(world, "not_finite", NAMES, inf)
    refused(world, "not_finite", NAMES, q, time_from_start=float("nan"))
    refused(world, "names", NAMES[:5] + ("elbow",), q, words=("unknown ['elbow']", "missing ['joint_6']"))
    refused(world, "names", NAMES[:5], q[:5], words=("missing",))
    refused(world, "names", NAMES, q[:5], words=("5 positions for 6",))
    refused(world, "names", NAMES[:5] + ("joint_1",), q, words=("repeated",))
    out = list(q)
    out[0] = 3.0                                                # J1 limit 2.705 rad
    refused(world, "limits", NAMES, out, words=("joint_1",))
    jump = list(q)
    jump[1] += 0.5                                              # 0.5 rad within 0.2 s: 2.5 rad/s
    text = refused(world, "speed", NAMES, jump, words=("joint_2", "% of its 2.09 rad/s"))
    assert "120 %" in text, text
    side = list(q)
    side[0] += 0.2                                              # Y = 1120 sin(0.2) = 222 mm > 100
    refused(world, "workspace", NAMES, side, time_from_start=0.2)
    # inside a running stream: the step from the last accepted command
    ok = list(q)
    ok[0] += 0.01
    job = world.core.joint_command(NAMES, ok)
    run_to(world, world.now + 0.02)
    jump = list(ok)
    jump[4] += 0.2                                              # J5: 0.2 rad in 0.02 s = 10 rad/s
    with pytest.raises(JointCommandRefused) as info:
        world.core.joint_command(NAMES, jump)
    assert info.value.kind == "speed" and "joint_5" in str(info.value)
    assert "last accepted command" in str(info.value)
    world.run_until(lambda: job.done, 1.0)
    assert len(job.points) == 1
    assert max(abs(a - b) for a, b in zip(world.arm.joints, ok)) <= world.core.wire.target_error + 1e-9


def test_time_from_start_sets_the_step_time(kin):
    """0.1 rad on J1 is too fast within 0.02 s but fine within 0.1 s (time_from_start)."""
    world = make(kin, "v2")
    q = list(world.arm.joints)
    q[0] += 0.1
    with pytest.raises(JointCommandRefused):
        world.core.joint_command(NAMES, q, 0.02)
    job = world.core.joint_command(NAMES, q, 0.1)
    assert job.points[0].speed == math.ceil(1000 * 0.1 / (0.1 * kin.limits.velocity[0]) - 1e-9)
    world.run_until(lambda: job.done, 1.0)


def test_protocol_v1_refuses_the_topic(kin):
    world = World(kin, protocol="v1")
    world.ready()
    q = list(world.arm.joints)
    with pytest.raises(JointCommandRefused) as info:
        world.core.joint_command(NAMES, q)
    assert info.value.kind == "protocol" and "cannot stream" in str(info.value) and "v1" in str(info.value)
    assert world.core.joint_commander.counters().refused["protocol"] == 1


def test_a_running_move_refuses_joint_command(kin):
    world = make(kin, "v2")
    move = world.core.submit(MoveRequest(MoveType.PTP, ControllerPose(1000, -600, 800, 0, 45, 0)))
    run_to(world, world.now + 0.2)
    assert not move.done
    with pytest.raises(JointCommandRefused) as info:
        world.core.joint_command(NAMES, list(world.status().joints))
    assert info.value.kind == "busy" and "job %d" % move.id in str(info.value)
    assert world.finish(move).success


def test_stop_motion_ends_the_stream_at_rest(kin):
    world = make(kin, "v2")
    q0 = tuple(world.arm.joints)
    _t0, _times, _commands, job = stream(world, sine(q0), duration=0.5)
    world.core.stop_motion("test stop")
    run_to(world, world.now + world.bus_period)                 # the sequencer took the stop
    assert job.closed and not job.done
    with pytest.raises(JointCommandRefused) as info:            # the arm is still braking
        world.core.joint_command(NAMES, list(world.status().joints))
    assert info.value.kind == "busy"
    world.run_until(lambda: job.done, 2.0)
    assert job.result.phase is JobPhase.CANCELLED and job.result.reached is not None
    q = list(world.arm.joints)
    q[0] += 0.001
    again = world.core.joint_command(NAMES, q)                  # a new stream from where it rests
    assert again is not job
    world.run_until(lambda: again.done, 1.0)


def test_a_trajectory_takes_over_from_the_stream(kin):
    world = make(kin, "v2")
    q0 = tuple(world.arm.joints)
    _t0, _times, _commands, job = stream(world, sine(q0), duration=0.4)
    end = tuple(v + 0.1 for v in q0)
    traj = trajectory(world, [1.0], [end])
    run = world.core.submit_trajectory(traj)
    with pytest.raises(JointCommandRefused) as info:            # the trajectory runs now: busy
        world.core.joint_command(NAMES, list(world.status().joints))
    assert info.value.kind == "busy"
    run_to(world, world.now + world.bus_period)              # the sequencer took it
    assert job.closed
    world.run_until(lambda: run.done, 5.0)
    assert run.success and job.done and job.result.phase is JobPhase.CANCELLED
    assert max(abs(a - b) for a, b in zip(world.arm.joints, end)) <= 0.001 * DEG


def test_joint_command_timeout_parameter():
    assert DriverParams.from_dict({}).joint_command_timeout == 0.2
    assert DriverParams.from_dict({"joint_command_timeout": 0.5}).joint_command_timeout == 0.5
    for bad in (0.0, -1.0, float("nan"), "fast", 6.0):
        with pytest.raises(ParamError) as info:
            DriverParams.from_dict({"joint_command_timeout": bad})
        assert info.value.name == "joint_command_timeout"
    with pytest.raises(ParamError) as info:                     # two bus cycles at 20 Hz: 0.1 s
        DriverParams.from_dict({"joint_command_timeout": 0.05})
    assert "two bus cycles" in str(info.value)


class _Point:
    def __init__(self, positions, time_from_start=0.0):
        self.positions = positions
        self.time_from_start = time_from_start


class _Duration:
    def __init__(self, s):
        self.s = s

    def to_sec(self):
        return self.s


def test_a_message_has_exactly_one_point(kin):
    world = make(kin, "v2")
    q = list(world.arm.joints)
    commander = world.core.joint_commander
    for points in ([], [_Point(q), _Point(q)]):
        with pytest.raises(JointCommandRefused) as info:
            commander.trajectory(NAMES, points)
        assert info.value.kind == "message" and "exactly one point" in str(info.value)
    assert commander.counters().refused["message"] == 2
    assert world.log.entries() == []
    q[0] += 0.1                                     # 0.1 rad: needs time_from_start 0.1 s
    with pytest.raises(JointCommandRefused):
        commander.trajectory(NAMES, [_Point(q, _Duration(0.02))])
    job = commander.trajectory(NAMES, [_Point(q, _Duration(0.1))])
    world.run_until(lambda: job.done, 1.0)
    assert job.result.success



def slowest_step(kin, job, times, commands):
    """The largest ratio, over the stream's points after the first, of the time the controller
    takes for the synchronous joint move from the point before it on the wire, at the point's
    speed, to the time the command was given for (the time since the command before it: no
    time_from_start). At most 1: the arm keeps up with the commands. A ratio far above 1 is a point
    whose speed was worked out from another predecessor than the one on the wire."""
    vmax = kin.limits.velocity
    ratios = []
    j = 0                                     # the command each point is (in order: a sine repeats values)
    for a, b in zip(job.points, job.points[1:]):
        j = next(k for k in range(j + 1, len(commands)) if commands[k] == b.joints)
        move = max(abs(y - x) / (b.speed / 1000.0 * v) for x, y, v in zip(a.joints, b.joints, vmax))
        ratios.append(move / (times[j] - times[j - 1]))
    return max(ratios)


def bus_stalls(world, every=0.07, length=0.045):
    """The driver's bus thread stands still for ``length`` every ``every`` seconds of world time
    (the interpreter lock held elsewhere, the machine loaded) while the commands keep coming: two or
    more reach the sequencer in one step."""
    tick = world.tick
    start = world.now

    def stalling_tick():
        world.frozen = (world.now - start) % every < length
        if not world.frozen and world.next_bus < world.now - world.bus_period:
            world.next_bus = world.now
        tick()
    world.tick = stalling_tick


@pytest.mark.parametrize("protocol", ["v2", "v3"])
@pytest.mark.parametrize("cycle_rate", [100.0, 40.0])
@pytest.mark.parametrize("stalls", [False, True], ids=["steady", "stalls"])
def test_every_point_runs_at_the_speed_of_its_own_step_through_the_turning_points(kin, protocol, cycle_rate,
                                                                                   stalls):
    """Where the sine turns, a command two or more back lies level with the new one: a speed worked
    out from there is the wire's slowest, 1, and the arm crawls the real step from the point before
    on the wire (a fresh clone's joint_command rostest stood 0.24 s at a trough and fell 3.3 deg
    behind). A replacement counts only from the point it was checked from: every point's speed
    moves the arm from its predecessor on the wire within the command's time."""
    world = make(kin, protocol, cycle_rate=cycle_rate)
    if stalls:
        bus_stalls(world)
    q0 = tuple(world.arm.joints)
    _t0, times, commands, job = stream(world, sine(q0, amp=2.0 * DEG, freq=1.0), duration=2.0)
    world.run_until(lambda: job.done, 2.0, "the stream's end")
    assert job.result.success, job.result.reason
    assert wire_seqs(world) == job.seqs
    ratio = slowest_step(kin, job, times, commands)
    print("%d points, %d replaced, slowest step %.2f of its time" % (len(job.points), job.replaced, ratio))
    assert ratio <= 1.0 + 1e-6


def bus_step(world):
    steps = len(world.bus_times)
    while len(world.bus_times) == steps:
        world.tick()


def test_a_replacement_checked_from_a_point_no_longer_last_on_the_wire_is_appended(kin):
    """The commander validates a replacement from the last point on the wire as the sequencer's
    view showed it; when the bus thread put another on the wire before the command was posted (a
    loaded node), the replacement would run a step from a point it was never checked from. The
    sequencer then appends the command instead (checked from the last accepted command)."""
    world = make(kin, "v2", cycle_rate=40.0)
    q0 = tuple(world.arm.joints)
    f = sine(q0, amp=2.0 * DEG, freq=1.0)
    _t0, _times, _commands, job = stream(world, f, duration=0.3)
    seq = world.core.joint_commander.jobs.sequencer
    t = 0.3
    for _ in range(200):                      # a moment with a point waiting behind two on the wire
        t += 0.01
        job = world.core.joint_command(NAMES, f(t), 0.02)
        bus_step(world)
        if seq._high >= 1 and len(job.points) - 1 > seq._high:
            break
    else:
        pytest.fail("no point ever waited behind the wire")
    before = job.points
    stale = job.points[seq._high - 1].joints          # the view one step behind
    q = f(t + 0.02)
    point = StreamPoint(q, 500, 1, before[-1].time + 0.02, len(before))
    world.core.joint_commander.jobs.extend_live(job, point, point, stale, world.now)
    bus_step(world)
    assert job.points[:len(before)] == before and job.points[-1] is point, "replaced, not appended"
    # the same command checked from the point really last on the wire replaces the waiting one
    anchor = job.points[seq._high].joints
    if len(job.points) - 1 > seq._high:
        q2 = f(t + 0.04)
        again = StreamPoint(q2, 500, 1, point.time + 0.02, len(job.points))
        n = len(job.points)
        world.core.joint_commander.jobs.extend_live(job, again, again, anchor, world.now)
        bus_step(world)
        assert len(job.points) == n and job.points[-1] is again
