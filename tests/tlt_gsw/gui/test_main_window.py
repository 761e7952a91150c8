"""The GUI live on a real ground link (CRS end in this process, loopback UDP), offscreen.

Clicks each command's button, confirms the hazardous ones, and reads each acknowledgement stage
in the command history; checks housekeeping limit colours, the decoded behaviour tree, the tower
view, the event log and the packet hex view on telemetry the CRS end sends.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from PySide6 import QtCore, QtGui, QtWidgets
from PySide6.QtTest import QTest

from tlt_common.bt.status_codec import TreeShape, encode
from tlt_common.ccsds.definitions import load_definitions
from tlt_common.mission.schema import load_mission
from tlt_gsw.archive.query import open_archive
from tlt_gsw.gui.archive_model import ArchiveModel
from tlt_gsw.gui.config import GuiConfig
from tlt_gsw.gui.demo_archive import demo_tree, set_demo_statuses
from tlt_gsw.gui.main_window import MainWindow
from tlt_gsw.gui.packet_view import hex_dump
from tlt_gsw.gui.style import LIMIT_COLOURS, STATUS_NAMES
from tlt_gsw.gui.tower_layout import INSPECTED, NOT_PLACED, PLACED, RIVETED, pack_member_states

DEFS = load_definitions()
TWO_BAY = load_mission(Path(__file__).resolve().parents[3] / "missions" / "two_bay.yaml")
YES, NO = QtWidgets.QMessageBox.StandardButton.Yes, QtWidgets.QMessageBox.StandardButton.No


@pytest.fixture
def gui(qapp, link_pair, wait_for):
    crs, worker, archive = link_pair
    conn = open_archive(archive)
    shape = TreeShape.of(demo_tree())
    model = ArchiveModel(
        conn, DEFS, shapes={"crs": TreeShape.from_definition(shape.definition())},
        plot_fields=[("hk_lifter", "position_0")],
    )  # fmt: skip
    window = MainWindow(model, GuiConfig(), archive_path=archive, sender=worker.submit, mission=TWO_BAY)
    window.show()

    def pump():
        qapp.processEvents()
        window.refresh()

    def until(predicate, timeout: float = 10.0):
        return wait_for(predicate, timeout=timeout, pump=pump)

    yield window, crs, until
    window.close()
    conn.close()


def answer_confirmation(yes: bool, seen: list[str]) -> None:
    """Click Yes or No on the confirmation dialog as soon as it is open (bounded retries)."""
    tries = [0]

    def click() -> None:
        box = QtWidgets.QApplication.activeModalWidget()
        if not isinstance(box, QtWidgets.QMessageBox):
            tries[0] += 1
            if tries[0] < 500:
                QtCore.QTimer.singleShot(10, click)
            return
        seen.append(box.text())
        box.button(YES if yes else NO).click()

    QtCore.QTimer.singleShot(0, click)


def history(window: MainWindow) -> dict[str, list[str]]:
    """Command -> [stages, reason, detail] of its newest row."""
    out: dict[str, list[str]] = {}
    for row in reversed(window.command_history.row_texts()):
        out[row[1]] = row[2:5]
    return out


def test_each_command_shows_its_acknowledgement_stages(gui):
    window, crs, until = gui
    panel = window.command_panel
    left = QtCore.Qt.MouseButton.LeftButton
    for name in ("start", "pause", "resume"):
        QTest.mouseClick(panel.buttons[name], left)
        until(lambda n=name: history(window).get(n, [""])[0] == "sent → accepted → completed")

    seen: list[str] = []
    answer_confirmation(True, seen)
    QTest.mouseClick(panel.buttons["stop"], left)
    assert seen and "STOP" in seen[0]
    until(lambda: history(window).get("stop", [""])[0] == "sent → accepted → completed")

    panel.bb_key.setText("lifter_speed")
    panel.bb_type.setCurrentText("float")
    panel.bb_value.setText("0.012")
    QTest.mouseClick(panel.buttons["set_blackboard_value"], left)
    until(lambda: history(window).get("set_blackboard_value", [""])[0] == "sent → accepted → completed")
    assert crs.handled[-1].params == {"key": "lifter_speed", "value": 0.012}
    panel.bb_key.setText("speed_of_light")
    QTest.mouseClick(panel.buttons["set_blackboard_value"], left)
    until(lambda: history(window)["set_blackboard_value"][0] == "sent → rejected")
    assert history(window)["set_blackboard_value"][1:] == ["refused", "speed_of_light is not ground-writable"]

    panel.act_name.setCurrentText("lifter")
    panel.act_state.setCurrentText("safe")
    seen.clear()
    answer_confirmation(True, seen)
    QTest.mouseClick(panel.buttons["set_actuator_state"], left)
    assert seen and "SET_ACTUATOR_STATE" in seen[0] and "actuator=lifter" in seen[0]
    until(lambda: history(window).get("set_actuator_state", [""])[0] == "sent → accepted → failed")
    assert history(window)["set_actuator_state"][1:] == ["execution_failed", "lifter is in Safe"]
    assert [c.name for c in crs.handled] == [
        "start", "pause", "resume", "stop", "set_blackboard_value", "set_actuator_state",
    ]  # fmt: skip


def test_declined_confirmation_and_bad_parameters_send_nothing(gui, qapp):
    window, crs, _until = gui
    panel = window.command_panel
    seen: list[str] = []
    answer_confirmation(False, seen)
    QTest.mouseClick(panel.buttons["stop"], QtCore.Qt.MouseButton.LeftButton)
    assert seen and "cancelled" in panel.status.text()
    panel.bb_key.setText("lifter_speed")
    panel.bb_type.setCurrentText("int")
    panel.bb_value.setText("fast")
    QTest.mouseClick(panel.buttons["set_blackboard_value"], QtCore.Qt.MouseButton.LeftButton)
    assert "not sent" in panel.status.text() and "fast" in panel.status.text()
    panel.act_name.setCurrentText("top_grippers")
    assert not panel.act_value.isEnabled()  # top grippers take no value
    for _ in range(10):
        qapp.processEvents()
        window.refresh()
    assert crs.handled == [] and window.command_history.rowCount() == 0


def test_a_tower_correction_is_sent_and_the_refusal_shows_why(gui):
    window, crs, until = gui
    panel = window.command_panel
    left = QtCore.Qt.MouseButton.LeftButton
    # The mission's members and dispensers are offered.
    assert panel.member.completer().model().rowCount() == len(TWO_BAY.members)
    panel.member.setText("bay1/vertical/x0_y1")
    panel.mark.setCurrentText("discarded")
    QTest.mouseClick(panel.buttons["correct_member"], left)
    until(lambda: history(window).get("set_blackboard_value", [""])[0] == "sent → rejected")
    assert history(window)["set_blackboard_value"][1:] == [
        "refused",
        "tower/bay1/vertical/x0_y1 is not ground-writable",
    ]
    panel.dispenser.setText("vertical_dispenser_x")
    panel.count.setValue(3)
    QTest.mouseClick(panel.buttons["correct_dispenser"], left)
    until(lambda: len(window.command_history.row_texts()) == 2)
    shown = [row[5] for row in window.command_history.row_texts()]
    assert "key=dispenser/vertical_dispenser_x, value=3" in shown, shown
    assert "key=tower/bay1/vertical/x0_y1, value=discarded" in shown, shown
    assert crs.handled == []  # both refused on arrival
    panel.member.clear()
    QTest.mouseClick(panel.buttons["correct_member"], left)
    assert "not sent: member: enter a member id" in panel.status.text()


def test_the_forms_offer_exactly_the_definitions_and_every_agents_keys(gui):
    window, _crs, _until = gui
    panel = window.command_panel
    assert [panel.act_name.itemText(i) for i in range(panel.act_name.count())] == list(DEFS.actuators)
    for actuator in DEFS.actuators.values():
        panel.act_name.setCurrentText(actuator.name)
        assert [panel.act_state.itemText(i) for i in range(panel.act_state.count())] == list(actuator.states)
        for state in actuator.states:
            panel.act_state.setCurrentText(state)
            assert panel.act_value.isEnabled() == (state in actuator.value_states), (actuator.name, state)
    panel.bb_key.setText("ars_x/motion_attempts")
    assert panel.bb_type.currentText() == "int"
    assert "1 .. 5" in panel.bb_key.toolTip() and "Tries of a failed motion" in panel.bb_key.toolTip()
    panel.bb_key.setText("lifter_speed")
    assert panel.bb_type.currentText() == "float" and "m/s" in panel.bb_key.toolTip()
    assert {"lifter_speed", "ars_x/settle_s", "ars_y/fire_s"} <= set(panel.keys)


def test_telemetry_views_show_what_the_crs_sends(gui, tmp_path):
    window, crs, until = gui
    link = crs.link
    lifter = link.send_telemetry("hk_lifter", {
        "state": "crs_control", "position_0": 2.5, "position_1": 0.5, "position_2": 0.5, "position_3": 1.95,
        "velocity": 100, "limit_switches": 0, "watchdog_tripped": False, "link_ok": True,
    })  # fmt: skip
    shape = TreeShape.of(demo_tree())
    set_demo_statuses(shape, 3)
    for part in encode(shape, agent="crs", tick_count=3, max_status_bytes=5):
        link.send_telemetry("tree_status", {
            "agent": part.agent, "shape_hash": part.shape_hash, "tick": part.tick_count,
            "node_count": part.node_count, "part_index": part.part_index, "part_count": part.part_count,
            "first_node": part.first_node, "status": part.status,
        })  # fmt: skip
    states = [INSPECTED] + [RIVETED] * 8 + [PLACED, PLACED] + [NOT_PLACED] * 11
    link.send_telemetry("hk_tower", {"member_count": 22, "member_states": pack_member_states(states)})
    link.send_telemetry("hk_mission", {
        "run_state": "running", "started": True, "bays_total": 2, "bays_built": 1, "current_bay": 2,
        "members_total": 22, "members_placed": 11, "members_riveted": 8, "current_step": "Far Verticals 2",
        "fault": "",
    })  # fmt: skip
    link.send_event(link_severity("error"), "LIFTER_ENCODER", "encoder 0 beyond its travel")
    model = window.model
    until(lambda: "crs" in model.trees and ("hk_mission", "") in model.housekeeping and model.events)

    window.show_tab("housekeeping")
    page = window.housekeeping.pages["hk_lifter"]
    red, yellow, nominal = page.cell("position_0"), page.cell("position_3"), page.cell("position_1")
    assert red.text() == "2.5000" and red.data(QtCore.Qt.ItemDataRole.UserRole) == "red"
    assert red.background().color() == QtGui.QColor(LIMIT_COLOURS["red"])
    assert yellow.data(QtCore.Qt.ItemDataRole.UserRole) == "yellow"
    assert yellow.background().color() == QtGui.QColor(LIMIT_COLOURS["yellow"])
    assert nominal.data(QtCore.Qt.ItemDataRole.UserRole) is None
    assert page.worst == "red"

    window.show_tab("tree")
    assert window.tree_view.node_rows() == [
        (n.path, STATUS_NAMES[s]) for n, s in zip(shape.nodes, shape.statuses(), strict=False)
    ]
    assert "tick 3" in window.tree_view.summary.text()

    window.show_tab("tower")
    tower = window.tower_view
    assert tower.member_state("bay1/cross_frame") == "inspected"
    assert tower.member_state("bay1/diagonal/face_y1") == "riveted"
    assert tower.member_state("bay2/vertical/x0_y1") == "placed"
    assert tower.member_state("foundation/x1_y1") == "not placed"
    assert "Bays built: 1 of 2" in tower.summary.text()

    events = window.event_log.row_texts()
    assert events[-1][1:] == [
        "ERROR",
        "crs.ground_link",
        "LIFTER_ENCODER",
        "none",
        "encoder 0 beyond its travel",
    ]

    window.show_tab("packets")
    lifter_row = next(p for p in model.packets if p.kind == "hk_lifter")
    text = window.packet_view.select_packet(lifter_row.id)
    assert hex_dump(lifter) in text and "position_0 = 2.5" in text
    assert window.link_status.values["link"].text() == "CONNECTED"

    shot = window.save_screenshot(tmp_path / "gsw.png")
    image = QtGui.QImage(str(shot))
    assert image.width() == window.width() and image.height() == window.height()


def link_severity(name: str):
    from tlt_common.ccsds.reasons import Severity

    return Severity[name.upper()]


def test_a_limit_crossed_is_an_event_and_an_alarm_until_acknowledged(gui):
    """Over the real link: a lifter position goes yellow, red, and back. Each crossing is an event
    with its value and limit; the alarm stays listed after the value is back until acknowledged,
    and an acknowledged alarm that gets worse asks again."""
    window, crs, until = gui
    link = crs.link
    model = window.model

    def lifter(position_3: float) -> None:
        link.send_telemetry("hk_lifter", {
            "state": "crs_control", "position_0": 0.5, "position_1": 0.5, "position_2": 0.5,
            "position_3": position_3, "velocity": 100, "limit_switches": 0, "watchdog_tripped": False,
            "link_ok": True,
        })  # fmt: skip

    for value in (0.5, 1.95, 1.95):
        lifter(value)
    until(lambda: any(e.code == "LIMIT_YELLOW" for e in model.events))
    (row,) = window.limit_alarms.row_texts()
    assert row[1:6] == ["hk_lifter.position_3", "YELLOW", "1.95 m", "[0, 1.9]", "1.95 m"]
    assert row[6] == "OUT, NOT acknowledged" and "1 not acknowledged" in window.limit_alarms.title()
    window.limit_alarms.ack_all.click()
    assert window.limit_alarms.row_texts()[0][6] == "OUT, acknowledged"
    lifter(2.05)  # worse than what was acknowledged
    until(lambda: any(e.code == "LIMIT_RED" for e in model.events))
    row = window.limit_alarms.row_texts()[0]
    assert row[2:5] == ["RED", "2.05 m", "[-0.01, 2]"] and row[6] == "OUT, NOT acknowledged"
    lifter(0.6)
    until(lambda: any(e.code == "LIMIT_OK" for e in model.events))
    assert window.limit_alarms.row_texts()[0][5:] == ["0.6 m", "back within limits, NOT acknowledged"]
    texts = [r[3:] for r in window.event_log.row_texts() if r[3].startswith("LIMIT_")]
    assert texts == [
        ["LIMIT_YELLOW", "none", "hk_lifter.position_3 = 1.95 m: outside its yellow limits [0, 1.9]"],
        ["LIMIT_RED", "none", "hk_lifter.position_3 = 2.05 m: outside its red limits [-0.01, 2]"],
        ["LIMIT_OK", "none", "hk_lifter.position_3 = 0.6 m: back within limits [-0.01, 2]"],
    ]
    table = window.limit_alarms.table
    table.selectRow(0)
    window.limit_alarms.ack_selected.click()
    assert window.limit_alarms.row_texts() == [], "acknowledged and back within limits: gone"
    assert not window.limit_alarms.ack_all.isEnabled()


def test_disabled_command_buttons_look_disabled(qapp):
    """The hazardous commands' buttons (Stop, Set Actuator State's Send) are dark red when they can
    be used and grey like every other button when they cannot (monitor only, replay)."""
    from tlt_gsw.gui.command_panel import CommandPanel

    def red_pixels(button: QtWidgets.QPushButton) -> int:
        image = button.grab().toImage()
        count = 0
        for y in range(image.height()):
            for x in range(image.width()):
                colour = image.pixelColor(x, y)
                count += colour.red() > 120 and colour.green() < 80 and colour.blue() < 80
        return count

    enabled = CommandPanel(DEFS, lambda name, params: None)
    disabled = CommandPanel(DEFS, None, "monitor only")
    for name in ("stop", "set_actuator_state"):
        on, off = enabled.buttons[name], disabled.buttons[name]
        assert on.isEnabled() and not off.isEnabled()
        assert red_pixels(on) > 20, f"{name}: the enabled button is drawn dark red"
        assert red_pixels(off) == 0, f"{name}: the disabled button is drawn in red"


def test_an_agents_tree_is_named_from_the_definition_it_sent_with_no_configuration(gui):
    """Live over the link: an ARS's status comes first (counts only, and why), then its definition
    (as the CRS forwards it); the tree view then names every node."""
    from tlt_common.bt.shape_definition import split_definition

    window, crs, until = gui
    link = crs.link
    shape = TreeShape.of(demo_tree().children[4])
    set_demo_statuses(shape, 2)

    def send_status(tick: int) -> None:
        for part in encode(shape, agent="ars_y", tick_count=tick, max_status_bytes=2):
            link.send_telemetry("tree_status", {
                "agent": part.agent, "shape_hash": part.shape_hash, "tick": part.tick_count,
                "node_count": part.node_count, "part_index": part.part_index, "part_count": part.part_count,
                "first_node": part.first_node, "status": part.status,
            })  # fmt: skip

    send_status(1)
    until(lambda: "ars_y" in window.model.trees)
    window.show_tab("tree")
    window.tree_view.agent.setCurrentText("ars_y")
    assert "received yet" in window.tree_view.summary.text() and window.tree_view.node_rows() == []
    for part in split_definition(shape, "ars_y", max_chunk_bytes=100):
        link.send_telemetry("tree_definition", part.fields())
    send_status(2)
    until(lambda: window.model.trees["ars_y"].decoded is not None)
    window.show_tab("housekeeping")
    window.show_tab("tree")
    assert window.tree_view.node_rows() == [
        (n.path, STATUS_NAMES[s]) for n, s in zip(shape.nodes, shape.statuses(), strict=True)
    ]
