"""What `rosrun vr_driver scan` makes of a scan's result (vr_driver.commission.scan), without a line: the
protocol a card's configuration fits, the card's owner, other masters, and the commands printed next
(or none). The scan on the virtual line over real ptys is test_scan_line.py."""
from __future__ import annotations

from pyprofibus_vendor.dp import SlaveDiag
from pyprofibus_vendor.fdl import StationType
from pyprofibus_vendor.scan import RateResult, ScanResult, StationFound

from vr_driver.commission.scan import format_findings, g2_findings, main, next_commands, protocol_cfg, protocol_fit
from vr_driver.protocol.v2 import CHK_CFG_V2
from vr_driver.protocol.v3 import CHK_CFG_V3

V1_CFG = bytes.fromhex("13 13 13 11 23 23 23 21")


def result(*stations: StationFound, rate: int = 187500, other_masters=None) -> ScanResult:
    r = RateResult(rate, stations={s.address: s for s in stations}, other_masters=dict(other_masters or {}))
    return ScanResult("/dev/ttyUSB3", 0, tuple(range(16)), [r])


def g2(address: int, cfg, owner: int = 0xFF) -> StationFound:
    return StationFound(address, StationType.SLAVE, diag=SlaveDiag(master_address=owner, ident=0x06C6), cfg=cfg)


def test_each_protocols_chk_cfg_fits_that_protocol():
    assert protocol_cfg("v1") == V1_CFG and protocol_cfg("v2") == CHK_CFG_V2 and protocol_cfg("v3") == CHK_CFG_V3
    for name in ("v1", "v2", "v3"):
        assert protocol_fit(protocol_cfg(name)).protocol == name
    # 14 bytes each way as two modules: v1's lengths, not v1's modules
    fit = protocol_fit(bytes.fromhex("1D 2D"))
    assert fit.protocol is None and fit.same_lengths == ("v1",)
    assert protocol_fit(bytes.fromhex("11 21")).same_lengths == ()


def test_a_v3_card_gets_the_commission_and_driver_lines():
    found = g2_findings(result(g2(6, CHK_CFG_V3)))
    assert next_commands(found) == [
        "rosrun vr_driver commission --port /dev/ttyUSB3 --baud 187500 --slave-address 6",
        "roslaunch vr_driver driver.launch sim:=false port:=/dev/ttyUSB3 baud:=187500 slave_address:=6 "
        "commissioning:=commissioning.yaml"]


def test_a_v1_card_gets_the_driver_line_and_is_told_what_commission_needs():
    found = g2_findings(result(g2(4, V1_CFG)))
    assert next_commands(found) == [
        "roslaunch vr_driver driver.launch sim:=false port:=/dev/ttyUSB3 baud:=187500 slave_address:=4 protocol:=v1"]
    text = "\n".join(format_findings(found))
    assert "its modules fit protocol v1" in text and "commission measures protocol v3 only" in text


def test_a_card_of_no_protocol_gets_no_command_but_the_modules_to_configure():
    found = g2_findings(result(g2(4, bytes.fromhex("1D 2D"))))
    assert next_commands(found) == []
    text = "\n".join(format_findings(found))
    assert "record lengths of protocol v1 but other modules" in text and "Cfg_Fault" in text
    found = g2_findings(result(g2(4, bytes.fromhex("10 20"))))
    assert "fit none of this driver's protocols" in "\n".join(format_findings(found))


def test_an_owned_card_and_another_master_are_named_and_block_the_commands():
    found = g2_findings(result(g2(4, CHK_CFG_V3, owner=2)))
    assert "parameterised by master 2: stop that master" in "\n".join(format_findings(found))
    found = g2_findings(result(rate=19200, other_masters={1: "passes the token to station 3"}))
    assert next_commands(found) == [] and "stop master 1 first" in "\n".join(format_findings(found))


def test_a_card_at_the_drivers_own_address_is_told_to_move_the_driver():
    text = "\n".join(format_findings(g2_findings(result(g2(2, CHK_CFG_V3)))))
    assert "the driver's own address is 2 too (master_address)" in text


def test_two_cards_and_no_card():
    found = g2_findings(result(g2(4, CHK_CFG_V3), g2(5, V1_CFG)))
    assert [s.address for s in found.g2] == [4, 5]
    assert "2 G2 cards on this line" in "\n".join(format_findings(found))
    assert "--slave-address 4" in next_commands(found)[0]
    island = StationFound(9, StationType.SLAVE, diag=SlaveDiag(ident=0x0F1A), cfg=bytes.fromhex("11 21"))
    found = g2_findings(result(island))
    text = "\n".join(format_findings(found))
    assert "no station has the G2 card's ident 0x06C6" in text and "station 9 (ident 0x0F1A" in text


def test_the_command_refuses_bad_options_before_opening_the_port(capsys):
    assert main(["--device", "/nonexistent/tty"]) == 3
    assert main(["--rates", "19200,7"]) == 2
    assert "outside 9600..12000000" in capsys.readouterr().err
