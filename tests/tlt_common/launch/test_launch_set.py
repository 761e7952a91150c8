"""Launch sets are refused before anything starts when a key is unknown, a type is wrong or a
required value is missing, with the file, the key and what was expected."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from tlt_common.config_schema import ConfigError
from tlt_common.launch import load_launch_set

CONFIG = Path(__file__).resolve().parents[3] / "config" / "launch"


def write(tmp_path: Path, body: str) -> Path:
    path = tmp_path / "set.yaml"
    path.write_text(textwrap.dedent(body))
    return path


def refused(tmp_path: Path, body: str) -> str:
    path = write(tmp_path, body)
    with pytest.raises(ConfigError) as info:
        load_launch_set(path, base_env={"PATH": "/usr/bin:/bin"})
    assert str(info.value).startswith(f"{path}: ")
    return str(info.value).removeprefix(f"{path}: ")


def test_a_full_set_resolves_arguments_parameters_and_environment(tmp_path):
    path = write(
        tmp_path,
        """
        name: demo
        grace_period_s: 2
        env: {SHARED: one}
        processes:
          - name: lifter
            executable: python
            args: ["${LAUNCH_DIR}/x.py", 3, "${SHARED}-${OWN}"]
            env: {OWN: two}
            node_name: lifter
            parameters: {rate_hz: 50, port: /dev/ttyACM0, joints: [a, b], safe: true}
            restart: always
            max_restarts: 2
            required: true
    """,
    )
    launch_set = load_launch_set(path, base_env={"PATH": "/usr/bin:/bin"})
    (proc,) = launch_set.processes
    assert launch_set.name == "demo" and launch_set.grace_period_s == 2.0
    assert proc.argv == (
        sys.executable,
        f"{tmp_path}/x.py",
        "3",
        "one-two",
        "--ros-args",
        "-r",
        "__node:=lifter",
        "-p",
        "rate_hz:=50",
        "-p",
        "port:=/dev/ttyACM0",
        "-p",
        "joints:=[a, b]",
        "-p",
        "safe:=true",
    )
    assert proc.env == {"SHARED": "one", "OWN": "two"}

    assert (proc.restart, proc.max_restarts, proc.required) == ("always", 2, True)


def test_variables_may_have_defaults(tmp_path):
    path = write(
        tmp_path,
        """
        processes:
          - {name: a, executable: python, args: ["${RUN_DIR:-/tmp/run}/x", "${HOME_ISH:-h}"],
             wait_for_path: "${RUN_DIR:-/tmp/run}/dev"}
    """,
    )
    (proc,) = load_launch_set(path, base_env={"HOME_ISH": "set"}).processes
    assert proc.argv[1:] == ("/tmp/run/x", "set")
    assert proc.wait_for_path == "/tmp/run/dev"


def test_defaults(tmp_path):
    launch_set = load_launch_set(
        write(
            tmp_path,
            """
        processes:
          - {name: a, executable: python}
    """,
        )
    )
    (proc,) = launch_set.processes
    assert launch_set.name == "set"
    assert (proc.restart, proc.required, proc.argv, proc.nice) == ("never", False, (sys.executable,), 0)
    assert proc.on_refusal == "continue"


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ("processes: []", "processes: no processes and nothing included"),
        ("name: x", "processes: no processes and nothing included"),
        ("include: [no_such_set.yaml]", "include[0]: no launch set at /"),
        (
            "processes:\n  - {name: a, executable: python, restrat: always}",
            "processes[0].restrat: unknown key (known keys: ",
        ),
        (
            "processes:\n  - {name: a, executable: python, max_restarts: many}",
            "processes[0].max_restarts: expected an integer, got str 'many'",
        ),
        (
            "processes:\n  - {name: a, executable: python, required: yes please}",
            "processes[0].required: expected true or false, got str 'yes please'",
        ),
        ("processes:\n  - {name: a}", "processes[0].executable: missing required key (program to run)"),
        (
            "processes:\n  - {name: a, executable: python}\n  - {name: a, executable: python}",
            "processes[1].name: duplicate process name 'a'",
        ),
        (
            "processes:\n  - {name: a, executable: tlt-no-such-program}",
            "processes[0].executable: executable 'tlt-no-such-program' not found in",
        ),
        (
            "processes:\n  - {name: a, executable: python, args: ['${NOT_SET}']}",
            "processes[0].args[0]: ${NOT_SET} is not set in the environment or the launch set",
        ),
        (
            "processes:\n  - {name: 2fast, executable: python}",
            "processes[0].name: expected a name of letters, digits and '_' starting with a letter, "
            "got '2fast'",
        ),
        (
            "grace_period_s: 0\nprocesses:\n  - {name: a, executable: python}",
            "grace_period_s: expected at least 0.1, got 0.0",
        ),
        (
            "processes:\n  - {name: a, executable: python, on_exit: shutdown}\n"
            "  - {name: b, executable: python, on_exit: shutdown}",
            "processes: at most one process may have on_exit: shutdown",
        ),
        (
            "processes:\n  - {name: a, executable: python, cwd: /no/such/dir}",
            "processes[0].cwd: /no/such/dir is not a directory",
        ),
        (
            "processes:\n  - {name: a, executable: python, nice: 20}",
            "processes[0].nice: expected at most 19, got 20",
        ),
        (
            "processes:\n  - {name: a, executable: python, nice: -5}",
            "processes[0].nice: expected at least 0, got -5",
        ),
        (
            "processes:\n  - {name: a, executable: python, on_refusal: restart}",
            "processes[0].on_refusal: expected one of 'continue', 'shutdown', got 'restart'",
        ),
        ("processes: [a", "invalid YAML: line 1, column 14: "),
    ],
)
def test_bad_sets_are_refused_naming_file_key_and_expectation(tmp_path, body, message):
    assert refused(tmp_path, body).startswith(message)


def test_included_sets_join_with_the_including_environment(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "devices.yaml").write_text(
        textwrap.dedent("""
        env: {LINKS: "${RUN:-/default}/links"}
        processes:
          - {name: emulator, executable: python, args: ["${LINKS}", "${LAUNCH_DIR}"]}
    """)
    )
    path = write(
        tmp_path,
        """
        env: {RUN: /run/here}
        include: [sub/devices.yaml]
        processes:
          - {name: job, executable: python, args: ["${LAUNCH_DIR}"], on_exit: shutdown}
    """,
    )
    emulator, job = load_launch_set(path, base_env={}).processes
    assert emulator.argv[1:] == ("/run/here/links", str(tmp_path / "sub"))
    assert emulator.env == {"RUN": "/run/here", "LINKS": "/run/here/links"}
    assert job.argv[1:] == (str(tmp_path),)


def test_an_included_name_may_not_repeat_and_a_set_may_not_include_itself(tmp_path):
    (tmp_path / "other.yaml").write_text("processes:\n  - {name: a, executable: python}\n")
    path = write(tmp_path, "include: [other.yaml]\nprocesses:\n  - {name: a, executable: python}\n")
    with pytest.raises(ConfigError, match=r"processes\[0\].name: duplicate process name 'a'"):
        load_launch_set(path)
    path.write_text("include: [set.yaml]\n")
    with pytest.raises(ConfigError, match=r"include\[0\]: set.yaml includes itself"):
        load_launch_set(path)


def test_a_missing_file_is_named():
    with pytest.raises(ConfigError, match=r"/no/such/set.yaml: cannot read file: No such file"):
        load_launch_set("/no/such/set.yaml")


@pytest.mark.parametrize("path", sorted(CONFIG.glob("*.yaml")), ids=lambda p: p.name)
def test_every_shipped_launch_set_is_valid(path):
    assert load_launch_set(path).processes


@pytest.mark.parametrize("camera_model", ["exact", "realistic"])
def test_the_twin_and_vision_are_given_one_camera_model(camera_model):
    """A launch set that runs the twin and vision tells both the same TLT_CAMERA_MODEL: vision
    taking a realistic camera's depth for exact (or the reverse) would certify what it should not."""
    checked = 0
    for path in sorted(CONFIG.glob("*.yaml")):
        processes = {
            p.name: p.argv for p in load_launch_set(path, {"TLT_CAMERA_MODEL": camera_model}).processes
        }
        models = {
            name: argv[argv.index("--camera-model") + 1]
            for name, argv in processes.items()
            if name in ("twin", "vision") and "--camera-model" in argv
        }
        if "twin" in processes and "vision" in processes:
            assert models == {"twin": camera_model, "vision": camera_model}, path.name
            checked += 1
    assert checked >= 3


@pytest.mark.parametrize("source", ["", "mask_rcnn"])
def test_tlt_segmentation_reaches_the_vision_node_of_the_twin_launch_sets(source):
    """TLT_SEGMENTATION picks vision's masks for a build on the twin (bench/build.py
    --segmentation); unset, the vision node's file decides."""
    argv = {
        p.name: p.argv
        for p in load_launch_set(CONFIG / "system_twin.yaml", {"TLT_SEGMENTATION": source}).processes
    }
    vision = argv["vision"]
    assert vision[vision.index("--segmentation") + 1] == source


@pytest.mark.parametrize(
    ("path", "agents"),
    [
        ("system_twin.yaml", ("crs", "ars_x", "ars_y", "vision")),
        ("host_crs.yaml", ("crs", "vision")),
        ("host_ars_x.yaml", ("ars_x",)),
        ("host_ars_y.yaml", ("ars_y",)),
    ],
)
def test_an_agent_that_refuses_its_mission_stops_the_set(path, agents):
    """The CRS, an ARS or vision refusing its configuration (exit 2: a mission its arm cannot
    reach) would refuse again when restarted: the set stops with its reason instead of running on
    without it (the mission job would ask for Start for hours)."""
    processes = {p.name: p for p in load_launch_set(CONFIG / path).processes}
    assert {name: processes[name].on_refusal for name in agents} == dict.fromkeys(agents, "shutdown")
