"""The I/O line wired into the driver core, stepped: DriverCore with ``bus_config`` io_line_bus.yaml and
``io_signals`` io_island_signals.yaml cycles the virtual controller (slave 4) and the virtual I/O island
(slave 8) over one in-memory multi-drop link with the fake clock of _world.World. Each station is
supervised on its own: the island unplugged never drops the arm's link, the controller cut never the
island's. No pty, no threads, no sleeps."""
from __future__ import annotations

import os

import pytest

from vr_driver.driver import LinkState, MoveRequest
from vr_driver.controller.io_island import IslandProgram, island_slave
from vr_driver.params import DriverParams, ParamError
from vr_driver.poses import ControllerPose, MoveType

from _world import World
from test_io_line_stepped import LineLink

CONFIG = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "config")
IO_PARAMS = {"bus_config": os.path.join(CONFIG, "io_line_bus.yaml"),
             "io_signals": os.path.join(CONFIG, "io_island_signals.yaml")}
FAR = ControllerPose(1000, -600, 800, 0, 45, 0)


class TimedLineLink(LineLink):
    """The line where each telegram and its reply take bus time (1 ms): a station answering later
    in a cycle answers later on the clock, as on a real line."""

    def respond(self, frame):
        self.clock.advance(0.001)
        return super().respond(frame)


class IoWorld(World):
    """The world with the island on the line (its program stepped with the controller's)."""

    def __init__(self, kin, params=None, protocol: str = "v1") -> None:
        super().__init__(kin, dict(IO_PARAMS, **(params or {})), protocol=protocol)
        self.island = island_slave(clock=self.clock)
        self.island_program = IslandProgram(self.island)
        self.link = TimedLineLink([self.slave, self.island], self.clock)   # before the core opens it

    def tick(self) -> None:
        self.island_program.step(self.clock.t)
        super().tick()

    @property
    def io(self):
        return self.core.io.snapshot()

    def station_online(self) -> bool:
        return self.io.station("io_island").online

    def value(self, name):
        return self.io.signal(name).value


@pytest.fixture
def world(kin):
    w = IoWorld(kin)
    w.ready()
    w.run_until(w.station_online, 3.0, "island online")
    return w


def test_the_bus_keeps_every_slave_with_the_controller_first():
    params = DriverParams.from_dict(dict(IO_PARAMS, port="/dev/x", slave_address=4))
    bus = params.bus()
    assert [s.address for s in bus.slaves] == [4, 8]
    signals = params.signal_map(bus)
    assert [s.name for s in signals.signals] == ["gripper_close", "gripper_closed", "part_present"]
    assert DriverParams.from_dict({"port": "/dev/x"}).signal_map(bus) is None


def test_a_bad_signal_map_stops_the_driver_naming_the_parameter(tmp_path, kin):
    bad = tmp_path / "signals.yaml"
    bad.write_text("stations:\n  io_island:\n    address: 8\n    signals:\n"
                   "      valve: {direction: out, type: int16, byte: 1}\n")
    with pytest.raises(ParamError) as err:
        World(kin, dict(IO_PARAMS, io_signals=str(bad)))
    assert err.value.name == "io_signals"
    assert "valve" in str(err.value) and "past the end" in str(err.value)
    with pytest.raises(ParamError) as err:
        DriverParams.from_dict(dict(IO_PARAMS, io_signals=str(tmp_path / "missing.yaml")))
    assert err.value.name == "io_signals" and "no such file" in str(err.value)


def test_a_station_at_the_controllers_address_is_refused(tmp_path):
    bad = tmp_path / "signals.yaml"
    bad.write_text("stations:\n  robot:\n    address: 4\n    signals:\n"
                   "      flag: {direction: out, type: bit, byte: 0, bit: 0}\n")
    params = DriverParams.from_dict(dict(IO_PARAMS, io_signals=str(bad), port="/dev/x"))
    with pytest.raises(ParamError) as err:
        params.signal_map(params.bus())
    assert err.value.name == "io_signals" and "controller" in str(err.value)


def test_without_a_signal_map_only_the_controller_is_cycled(kin):
    w = World(kin, {"bus_config": IO_PARAMS["bus_config"]})
    w.ready()
    assert w.core.io is None
    assert [h.address for h in w.core.link._master.slaves] == [4]


def test_set_gripper_while_the_arm_moves(world):
    job = world.core.submit(MoveRequest(MoveType.LIN, FAR))
    world.run_until(lambda: world.arm.moving, 5.0, "arm moving")
    result = world.core.io.write("gripper_close", "1")
    assert result.success, result.message
    took = world.run_until(lambda: world.value("gripper_closed") == 1, 1.0, "gripper closed")
    assert 0.3 <= took <= 0.3 + 4 * world.bus_period          # the island's delay + a few cycles
    assert world.core.io.read("gripper_closed").value == "1"
    assert world.island.outputs[0] & 1 == 1
    assert world.finish(job).success
    counters = world.status().counters
    assert (counters.losses, counters.stalled_cycles) == (0, 0)


def test_the_island_unplugged_never_drops_the_arm_and_comes_back_safe(world):
    assert world.core.io.write("gripper_close", 1).success
    world.run_until(lambda: world.island.outputs[0] & 1, 1.0, "output at the island")
    job = world.core.submit(MoveRequest(MoveType.LIN, FAR))
    world.run_until(lambda: world.arm.moving, 5.0, "arm moving")
    world.link.unplugged.add(8)
    unplugged = world.now
    took = world.run_until(lambda: not world.station_online(), 2.0, "island offline")
    assert took <= world.params.link_timeout + 2 * world.bus_period
    assert world.value("gripper_closed") is None                 # never an old value as live
    assert not world.core.io.write("gripper_close", 1).success   # refused while offline
    world.run_until(lambda: world.now - unplugged > 2.0, 3.0)
    assert world.status().link is LinkState.CONNECTED
    world.link.unplugged.discard(8)
    world.run_until(world.station_online, 5.0, "island back")
    assert world.value("gripper_close") == 0                     # the safe value, until set again
    assert world.io.station("io_island").outputs_safe and world.io.station("io_island").losses == 1
    assert world.finish(job).success
    counters = world.status().counters
    assert (counters.losses, counters.stalled_cycles) == (0, 0)


def test_the_controller_cut_never_drops_the_island(world):
    world.link.unplugged.add(4)
    world.run_until(lambda: world.status().link is not LinkState.CONNECTED, 2.0, "link lost")
    world.run_for(2.0)
    assert world.station_online() and world.io.station("io_island").losses == 0
    assert world.core.io.write("gripper_close", "on").success
    world.run_until(lambda: world.value("gripper_closed") == 1, 1.0, "gripper closed")
    world.link.unplugged.discard(4)
    world.ready()


# ------------------------------------------------------------------ the controller's own I/O (v2)
V2_PARAMS = {"bus_config": os.path.join(CONFIG, "io_line_bus_v2.yaml"),
             "io_signals": os.path.join(CONFIG, "io_controller_signals_v2.yaml")}


@pytest.fixture
def world_v2(kin):
    w = IoWorld(kin, V2_PARAMS, protocol="v2")
    w.ready()
    w.run_until(lambda: w.station_online() and w.io.station("g2").online, 3.0, "stations online")
    return w


def test_the_controllers_own_io_is_a_station_in_v2(world_v2):
    w = world_v2
    assert w.value("g2_gripper_close") == 0 and w.value("g2_gripper_closed") == 0
    result = w.core.io.write("g2_gripper_close", "1")
    assert result.success, result.message
    w.run_until(lambda: w.program.io_outputs == 1, 1.0, "controller output 1")
    t_set = w.now
    w.run_until(lambda: w.value("g2_gripper_closed") == 1, 2.0, "g2_gripper_closed")
    assert w.now - t_set >= 0.3 - 1e-9
    w.program.set_input(3, True)
    w.run_until(lambda: w.value("g2_part_present") == 1, 1.0, "g2_part_present")
    assert not w.core.io.write("g2_gripper_closed", "1").success          # an input
    assert not w.core.io.write("g2_gripper_close", "2").success           # not a bit
    assert w.program.io_outputs == 1                                       # refusals changed nothing
    # the island beside it is untouched and still works
    assert w.core.io.write("gripper_close", "1").success
    w.run_until(lambda: w.value("gripper_closed") == 1, 2.0, "island gripper")


def test_the_controllers_outputs_go_safe_on_a_link_loss_and_stay_safe(world_v2):
    w = world_v2
    assert w.core.io.write("g2_gripper_close", "1").success
    w.run_until(lambda: w.program.io_outputs == 1, 1.0, "controller output 1")
    w.link.cut = True
    w.run_until(lambda: not w.io.station("g2").online, 1.0, "g2 offline")
    assert w.value("g2_gripper_closed") is None                            # never an old value
    w.run_until(lambda: w.program.io_outputs == 0, 2.0, "controller outputs safe")
    w.link.cut = False
    w.run_until(lambda: w.io.station("g2").online, 10.0, "g2 back")
    w.run_for(1.0)
    assert w.value("g2_gripper_close") == 0 and w.program.io_outputs == 0  # until set again


def test_the_controllers_own_io_needs_v2_and_safe_zero(tmp_path):
    params = DriverParams.from_dict(dict(V2_PARAMS, port="/dev/x", protocol="v1",
                                         bus_config=IO_PARAMS["bus_config"]))
    with pytest.raises(ParamError) as err:
        params.signal_map(params.bus())
    assert err.value.name == "io_signals" and "needs a protocol that carries it (v2;" in str(err.value)
    bad = tmp_path / "signals.yaml"
    bad.write_text("stations:\n  g2:\n    address: 4\n    signals:\n"
                   "      lamp: {direction: out, type: bit, byte: 0, bit: 0, safe: 1}\n")
    params = DriverParams.from_dict(dict(V2_PARAMS, io_signals=str(bad), port="/dev/x", protocol="v2"))
    with pytest.raises(ParamError) as err:
        params.signal_map(params.bus())
    assert "must be 0" in str(err.value) and "lamp" in str(err.value)
