"""``tlt mission-check`` runs the ARSs' own start-up checks: a mission of 0.70 m bays, which the
ARSs refuse at start-up (their arms cannot place a diagonal or rivet it), is refused by the check
before anything starts, every unreachable step named with its member, ARS and reason."""

from __future__ import annotations

import io
import re
from pathlib import Path

import pytest
import rclpy
import yaml

from tlt_ars.config import ars_config_from_dict, default_config_path
from tlt_ars.mission_check_cli import main
from tlt_ars.node import ArsNode
from tlt_ars.planning.reachability import UnreachableMember
from tlt_common.cli import main as tlt_main
from tlt_common.config_schema import load_yaml
from tlt_common.mission.generate import build

MISSIONS = Path(__file__).resolve().parents[2] / "missions"


@pytest.fixture(scope="module")
def narrow_mission(tmp_path_factory) -> Path:
    """One bay of 0.70 m, as ``tlt mission-generate --bays 1 --width 0.70 --height 0.70`` writes it."""
    path = tmp_path_factory.mktemp("missions") / "one_bay_070.yaml"
    path.write_text(yaml.safe_dump(build("one_bay_070", 1, width=0.70, height=0.70), sort_keys=False))
    return path


def run(*argv: str) -> tuple[int, list[str]]:
    out = io.StringIO()
    return main(list(argv), out=out), out.getvalue().splitlines()


def test_a_mission_out_of_the_arms_reach_is_refused_naming_each_step(narrow_mission):
    code, lines = run(str(narrow_mission))
    assert code == 1
    assert lines[0].startswith(f"ok {narrow_mission}: mission 'one_bay_070', 1 bay(s)")  # the file is valid
    unreachable = [line for line in lines if line.startswith("UNREACHABLE ")]
    pattern = re.compile(
        rf"^UNREACHABLE {re.escape(str(narrow_mission))}: (\S+): (ars_[xy]) cannot ([^:]+): (.+)$"
    )
    found = {(m[1], m[2], m[3]) for m in map(pattern.match, unreachable) if m and "IK solution" in m[4]}
    assert len(found) == len(unreachable)
    assert ("bay1/diagonal/face_y0", "ars_x", "place") in found
    assert ("bay1/diagonal/face_x1", "ars_y", "place") in found
    for ars in ("ars_x", "ars_y"):
        assert any(
            re.match(rf"FAIL {re.escape(str(narrow_mission))}: {ars}: \d+ unreachable step", x) for x in lines
        )

    # The file's own checks and the dispensers' coarse poses pass: the reach check is what refuses it.
    code, lines = run(str(narrow_mission), "--no-reach-check")
    assert code == 0 and len(lines) == 3 and all(line.startswith("ok ") for line in lines)


def test_the_ars_refuses_the_same_steps_at_start_up(narrow_mission):
    _, lines = run(str(narrow_mission))
    prefix = f"UNREACHABLE {narrow_mission}: "
    checked = [line.removeprefix(prefix) for line in lines if line.startswith(prefix) and ": ars_x " in line]
    raw = {**load_yaml(default_config_path("ars_x")), "mission": str(narrow_mission)}
    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        with pytest.raises(UnreachableMember) as refused:
            ArsNode(ars_config_from_dict(raw), context=context)
    finally:
        rclpy.try_shutdown(context=context)
    assert [str(issue) for issue in refused.value.issues] == checked


def test_the_tlt_command_runs_it_and_a_shipped_mission_passes(capsys):
    assert tlt_main(["mission-check", str(MISSIONS / "one_bay.yaml")]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split(":")[1].strip() for line in lines if line.startswith("ok ")][1:] == ["ars_x", "ars_y"]
    assert not [line for line in lines if line.startswith(("UNREACHABLE", "FAIL", "INVALID"))]
