"""``tlt ars-state``: an engineer reads an ARS's state file and settles a step left in doubt."""

from __future__ import annotations

from tlt_ars.mission_state import Request
from tlt_ars.request_data import RequestData, RequestFile
from tlt_common.cli import main as tlt
from tlt_common.mission.schema import load_mission

MISSION_FILE = "missions/two_bay.yaml"
MISSION = load_mission(MISSION_FILE)
MEMBER = "bay1/vertical/x0_y1"
Q = (0.1, -1.2, 1.5, -1.9, -1.6, 0.3)


def _in_doubt(path, holding: str | None = "vertical") -> RequestFile:
    """A state file as an ARS killed while its gun fired leaves it."""
    file = RequestFile(path, MISSION, "ars_x")
    file.save(
        RequestData(
            request=Request("add_member", MEMBER, "ars_x", bay=1, kind=1, position="x0_y1"),
            member=MISSION.member(MEMBER),
            holding=holding,
            dispenser="vertical_dispenser_x" if holding else None,
            setting="placed",
            setting_q=Q,
        )
    )
    return file


def _run(action: str, path, *extra: str) -> int:
    return tlt(["ars-state", action, str(path), "--ars", "ars_x", "--mission", MISSION_FILE, *extra])


def test_show_says_what_is_in_doubt_and_what_the_ars_will_do(tmp_path, capsys):
    path = tmp_path / "ars_x_request.json"
    _in_doubt(path)
    assert _run("show", path) == 0
    out = capsys.readouterr().out
    assert "request: add_member of 'bay1/vertical/x0_y1'" in out
    assert "in doubt: the step that sets the member placed began" in out
    assert "[0.100, -1.200, 1.500, -1.900, -1.600, 0.300] rad" in out
    assert "holding: a vertical from 'vertical_dispenser_x'" in out


def test_resolved_set_the_member_is_kept_placed_and_the_request_sent_again_finishes_it(tmp_path, capsys):
    path = tmp_path / "ars_x_request.json"
    file = _in_doubt(path)
    assert _run("resolve", path, "--set") == 0
    kept = file.load()
    assert (kept.recorded, kept.setting, kept.setting_q, kept.holding) == ("placed", "", None, "vertical")
    assert "member placed: sent again, the request lets go of it and retreats" in capsys.readouterr().out
    assert kept.unfinished()  # sent again, finished: a restarted ARS marks it placed from the file


def test_resolved_not_set_the_request_runs_afresh_and_a_held_part_stays_known(tmp_path):
    path = tmp_path / "ars_x_request.json"
    file = _in_doubt(path)
    assert _run("resolve", path, "--not-set") == 0
    kept = file.load()
    assert (kept.recorded, kept.setting, kept.holding) == ("", "", "vertical")
    assert not kept.unfinished()  # sent again it runs afresh: the held part is discarded first


def test_resolved_not_set_with_nothing_held_leaves_no_file(tmp_path):
    path = tmp_path / "ars_x_request.json"
    _in_doubt(path, holding=None)  # a cross frame let go of, say, then taken away by hand
    assert _run("resolve", path, "--not-set") == 0
    assert not path.exists()


def test_resolve_wants_a_step_in_doubt_and_an_answer(tmp_path, capsys):
    path = tmp_path / "ars_x_request.json"
    _in_doubt(path)
    assert _run("resolve", path) == 2
    assert "resolve needs --set or --not-set" in capsys.readouterr().err
    assert _run("resolve", path, "--set") == 0
    assert _run("resolve", path, "--set") == 2
    assert "nothing in doubt" in capsys.readouterr().err


def test_clear_removes_the_file_and_a_bad_file_is_refused_with_its_reason(tmp_path, capsys):
    path = tmp_path / "ars_x_request.json"
    _in_doubt(path)
    assert tlt(["ars-state", "show", str(path), "--ars", "ars_y", "--mission", MISSION_FILE]) == 2
    assert "belongs to 'ars_x', not to 'ars_y'" in capsys.readouterr().err
    assert _run("clear", path) == 0 and not path.exists()
    assert _run("show", path) == 0
    assert "no state file: the ARS holds nothing" in capsys.readouterr().out
