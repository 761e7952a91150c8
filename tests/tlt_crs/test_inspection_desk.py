"""The inspection desk between ``/crs/inspect_part`` calls and the tree: a presentation nobody
inspected is answered at once (or when withdrawn, or out of time) with a report that is not passed
and says ``not_inspected``, so the ARS keeps the part; only the tree's answer judges it."""

from __future__ import annotations

import threading

from tlt_interfaces.msg import InspectionReport

from tlt_crs.inspection_desk import InspectionDesk

MEMBER = "bay1/vertical/x0_y1"


def _serve_in_thread(desk, member=MEMBER, timeout=5.0):
    answer = {}
    thread = threading.Thread(
        target=lambda: answer.setdefault("report", desk.serve(member, "vertical", "zed_1", timeout))
    )
    thread.start()
    return thread, answer


def test_a_part_nobody_expects_is_not_inspected_and_says_why():
    desk = InspectionDesk()
    report = desk.serve(MEMBER, "vertical", "zed_1", 5.0)
    assert report.not_inspected and not report.passed
    assert report.reasons == ["the CRS is not expecting a part for inspection"]
    desk.expect("bay1/vertical/x1_y1")
    report = desk.serve(MEMBER, "vertical", "zed_1", 5.0)
    assert report.not_inspected and "expects a part for 'bay1/vertical/x1_y1'" in report.reasons[0]


def test_the_trees_verdict_is_a_judgement_withdrawal_and_time_out_are_not():
    desk = InspectionDesk()
    desk.expect(MEMBER)
    thread, answer = _serve_in_thread(desk)
    while desk.take(MEMBER) is None:
        pass
    verdict = InspectionReport(target_id=MEMBER, passed=False, reasons=["end fitting b missing"])
    assert desk.answer(MEMBER, verdict)
    thread.join(5.0)
    assert not answer["report"].not_inspected and answer["report"].reasons == ["end fitting b missing"]

    thread, answer = _serve_in_thread(desk)
    while desk.take(MEMBER) is None:
        pass
    desk.withdraw(MEMBER, "the CRS stopped following this request")
    thread.join(5.0)
    assert answer["report"].not_inspected and "withdrawn" in answer["report"].reasons[0]

    desk.expect(MEMBER)
    report = desk.serve(MEMBER, "vertical", "zed_1", 0.05)
    assert report.not_inspected and report.reasons == ["the CRS did not inspect the part within 0.05 s"]


def test_a_call_made_again_takes_over_and_gets_the_verdict():
    """Its ARS gave the first call up (out of time while the CRS was held): the first call's thread
    is released, and the verdict the tree reached on the part goes to the call waiting now."""
    desk = InspectionDesk()
    desk.expect(MEMBER)
    first, first_answer = _serve_in_thread(desk)
    while desk.take(MEMBER) is None:
        pass
    taken = desk.take(MEMBER)
    second, second_answer = _serve_in_thread(desk)
    first.join(5.0)
    assert first_answer["report"].not_inspected
    assert first_answer["report"].reasons == [f"a newer call for '{MEMBER}' took over"]
    while desk.take(MEMBER) is taken:
        pass
    assert desk.answer(MEMBER, InspectionReport(target_id=MEMBER, passed=True))
    second.join(5.0)
    assert second_answer["report"].passed and not second_answer["report"].not_inspected


def test_a_verdict_with_no_call_waiting_is_not_given_away():
    """The call ran out of time: answer says so, and the tree waits for the part to be presented
    again instead of sending the verdict to nobody."""
    desk = InspectionDesk()
    desk.expect(MEMBER)
    report = desk.serve(MEMBER, "vertical", "zed_1", 0.05)
    assert report.not_inspected
    assert not desk.answer(MEMBER, InspectionReport(target_id=MEMBER, passed=True))
    thread, answer = _serve_in_thread(desk)
    while desk.take(MEMBER) is None:
        pass
    assert desk.answer(MEMBER, InspectionReport(target_id=MEMBER, passed=True))
    thread.join(5.0)
    assert answer["report"].passed


def test_a_stopping_crs_releases_the_call_it_holds_and_holds_no_more():
    """The CRS's exit waits for its service threads: a call held for the whole hand-off time
    (a minute) kept a stopping CRS alive until the launcher killed it."""
    desk = InspectionDesk()
    desk.expect(MEMBER)
    thread, answer = _serve_in_thread(desk, timeout=60.0)
    while desk.take(MEMBER) is None:
        pass
    desk.close("the CRS is stopping")
    thread.join(5.0)
    assert not thread.is_alive()
    assert answer["report"].not_inspected and answer["report"].reasons == ["the CRS is stopping"]
    desk.expect(MEMBER)  # a tick still running meanwhile
    report = desk.serve(MEMBER, "vertical", "zed_1", 60.0)
    assert report.not_inspected and report.reasons == ["the CRS is stopping"]
