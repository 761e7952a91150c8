"""The inspection desk between ``/crs/inspect_part`` calls and the tree: a presentation nobody
inspected is answered at once (or when withdrawn, or out of time) with a report that is not passed
and says ``not_inspected``, so the ARS keeps the part; only the tree's answer judges it."""

from __future__ import annotations

import threading

from tlt_interfaces.msg import InspectionReport

from tlt_crs.behaviours.inspection import InspectionDesk

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
    while (pending := desk.take(MEMBER)) is None:
        pass
    desk.answer(pending, InspectionReport(target_id=MEMBER, passed=False, reasons=["end fitting b missing"]))
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


def _taken(desk):
    while (pending := desk.take(MEMBER)) is None:
        pass
    return pending


def test_a_part_presented_again_gets_the_verdict_on_the_call_the_tree_took():
    # The ARS was paused mid-call (a CRS fault held the build): it gave its call up and presents
    # the same part again while the tree inspects the part of the first call.
    desk = InspectionDesk()
    desk.expect(MEMBER)
    first, first_answer = _serve_in_thread(desk)
    taken = _taken(desk)
    second, second_answer = _serve_in_thread(desk)
    first.join(5.0)
    assert first_answer["report"].not_inspected and "presented again" in first_answer["report"].reasons[0]
    desk.answer(taken, InspectionReport(target_id=MEMBER, passed=True))
    second.join(5.0)
    assert second_answer["report"].passed and not second_answer["report"].not_inspected


def test_a_pass_answers_a_part_presented_again_after_its_call_was_given_up():
    # The tree answered the call it took, but the ARS had given that call up (paused mid-call).
    desk = InspectionDesk()
    desk.expect(MEMBER)
    thread, _ = _serve_in_thread(desk)
    desk.answer(_taken(desk), InspectionReport(target_id=MEMBER, passed=True))
    thread.join(5.0)
    for _ in range(2):
        report = desk.serve(MEMBER, "vertical", "zed_1", 0.05)
        assert report.passed and not report.not_inspected


def test_a_verdict_no_call_waits_for_answers_the_next_call_at_once():
    desk = InspectionDesk()
    desk.expect(MEMBER)
    thread, answer = _serve_in_thread(desk, timeout=0.3)
    taken = _taken(desk)
    thread.join(5.0)  # the call ran out of time while the CRS was held
    assert answer["report"].not_inspected
    desk.answer(taken, InspectionReport(target_id=MEMBER, passed=False, reasons=["end fitting b missing"]))
    report = desk.serve(MEMBER, "vertical", "zed_1", 0.05)
    assert not report.passed and not report.not_inspected and report.reasons == ["end fitting b missing"]
    # A failed part is discarded: the next presentation is a new part, which waits for its verdict.
    assert desk.serve(MEMBER, "vertical", "zed_1", 0.05).not_inspected

    # A new request for the member, or its withdrawal, drops a verdict nobody took.
    for drop in (lambda: desk.expect(MEMBER), lambda: desk.withdraw(MEMBER, "request finished")):
        desk.expect(MEMBER)
        thread, _ = _serve_in_thread(desk, timeout=0.1)
        taken = _taken(desk)
        thread.join(5.0)
        desk.answer(taken, InspectionReport(target_id=MEMBER, passed=True))
        drop()
        desk.expect(MEMBER)
        assert desk.serve(MEMBER, "vertical", "zed_1", 0.05).not_inspected
