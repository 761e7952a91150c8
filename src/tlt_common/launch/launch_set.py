"""Launch sets: which processes to start, with what parameters, environment and restart policy.

A launch set is a YAML file under ``config/launch/``. It is validated completely before anything
starts, so a typo never leaves half a system running. Example::

    name: lifter_on_emulator
    grace_period_s: 5.0          # SIGINT, then SIGTERM, then SIGKILL, each after this long
    env: {PYTHONUNBUFFERED: "1"}   # for every process
    processes:
      - name: lifter
        executable: tlt-lifter   # looked up in the venv's bin/, then PATH; "python" is this interpreter
        args: [--config, "${LAUNCH_DIR}/../hardware/lifter.yaml"]
        node_name: lifter        # appended as --ros-args -r __node:=lifter
        parameters: {rate_hz: 50}  # appended as --ros-args -p rate_hz:=50
        restart: on-failure      # never | on-failure | always
        max_restarts: 3
        required: true           # if it dies for good, the whole set stops with a non-zero exit
        wait_for_path: /tmp/tlt/lifter  # start only once this exists (an emulator's pty link)
        host: crs                # run inside this emulated host (see hosts below)
        nice: 5                  # lower CPU priority (0-19; every thread the process starts)
      - name: exercise
        executable: python
        args: [-m, some.job]
        on_exit: shutdown        # when it ends, stop the set and exit with its exit code

A process that exits with status 2 has *refused* to run: the project's processes (the CRS, the
ARSs, vision, the drivers, the twin) exit 2 when they reject their configuration or input (a
mission they cannot build, a file that does not validate), and start again only to refuse again.
``on_refusal: shutdown`` marks a process the set cannot do without: its refusal is not restarted,
and the whole set stops at once with status 2, its reason (the last line it wrote) repeated once
everything has stopped. By default (``continue``) a refusal is a failure like any other, which the
restart policy may restart (a driver whose device was not there yet).

A set may declare emulated hosts (network namespaces on one machine, ``tlt_common.launch.hosts``)
and place processes into them, by ``host:`` or, for processes of included sets, ``placement:``::

    hosts:
      - {name: crs, address: 10.77.0.11/24}
      - {name: twin, address: 10.77.0.10/24, extra_addresses: [10.77.0.21/24]}
    placement: {lifter: crs}     # process name -> host
    dds_profile: ../dds/emulated_hosts.xml   # Fast DDS profile template (this one by default)
    host_multicast: false        # the emulated switch drops multicast unless this is true

``${VAR}`` (or ``${VAR:-default}``) in ``executable``, ``args``, ``cwd``, ``env`` and
``wait_for_path`` values expands from the launcher's
environment, the set's ``env``, the process's ``env``, and ``LAUNCH_DIR`` (the set's folder).
"""

from __future__ import annotations

import dataclasses
import os
import re
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from tlt_common.config_schema import ConfigError, Field, load_yaml, opt, validate
from tlt_common.launch.dds_profile import DEFAULT_PROFILE
from tlt_common.launch.hosts import HostsError, HostSpec, check_addresses, check_host_name

RESTART_POLICIES = ("never", "on-failure", "always")
ON_EXIT = ("continue", "shutdown")
ON_REFUSAL = ("continue", "shutdown")
# The exit status of a process that refuses its configuration or input (and of a set it stopped).
REFUSED = 2
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)(?::-([^}]*))?\}")


def _name_check(value: str) -> str | None:
    if not _NAME.match(value):
        return f"expected a name of letters, digits and '_' starting with a letter, got {value!r}"
    return None


_SCALAR = Field(
    "any",
    check=lambda v: (
        None
        if isinstance(v, str | int | float | bool)
        else f"expected a string, number or boolean, got {type(v).__name__}"
    ),
)

PROCESS_SCHEMA: dict[str, Field] = {
    "name": Field("str", check=_name_check, doc="the process name, unique in the set"),
    "executable": Field("str", doc="program to run"),
    "args": opt(
        "list",
        [],
        item=Field(
            "any",
            check=lambda v: (
                None
                if isinstance(v, str | int | float)
                else f"expected a string or number, got {type(v).__name__}"
            ),
        ),
    ),
    "node_name": opt("str", None, check=_name_check),
    "parameters": opt(
        "map",
        {},
        item=Field(
            "any",
            check=lambda v: (
                None
                if isinstance(v, str | int | float | bool | list)
                else f"expected a scalar or list, got {type(v).__name__}"
            ),
        ),
    ),
    "env": opt("map", {}, item=_SCALAR),
    "cwd": opt("str", None),
    "restart": opt("str", "never", choices=RESTART_POLICIES),
    "max_restarts": opt("int", 5, minimum=0),
    "restart_delay_s": opt("float", 1.0, minimum=0.0),
    "required": opt("bool", False),
    "on_exit": opt("str", "continue", choices=ON_EXIT),
    "on_refusal": opt(
        "str",
        "continue",
        choices=ON_REFUSAL,
        doc=f"what an exit with status {REFUSED} (the process refused its configuration) does to the set",
    ),
    "wait_for_path": opt("str", None, doc="start once this path exists (e.g. a device link)"),
    "wait_timeout_s": opt("float", 30.0, minimum=0.0),
    "startup_s": opt(
        "float",
        3.0,
        minimum=0.0,
        doc="an exit within this long after start is reported as a failure to start",
    ),
    "host": opt("str", None, doc="the emulated host (a name under hosts:) the process runs in"),
    "nice": opt(
        "int",
        0,
        minimum=0,
        maximum=19,
        doc="niceness the process starts with: it yields the CPU to processes of lower niceness",
    ),
}

HOST_SCHEMA: dict[str, Field] = {
    "name": Field("str", check=check_host_name, doc="the host's name; its namespace is tlt-<run>-<name>"),
    "address": Field("str", doc="IPv4 address with prefix length, e.g. 10.77.0.11/24"),
    "extra_addresses": opt("list", [], item=Field("str"), doc="more addresses on the host's eth0"),
}

LAUNCH_SET_SCHEMA: dict[str, Field] = {
    "name": opt("str", None),
    "description": opt("str", ""),
    "grace_period_s": opt("float", 5.0, minimum=0.1),
    "env": opt("map", {}, item=_SCALAR),
    "include": opt("list", [], item=Field("str"), doc="launch sets whose processes join this one"),
    "processes": opt("list", [], item=Field("dict", schema=PROCESS_SCHEMA)),
    "hosts": opt(
        "list",
        [],
        item=Field("dict", schema=HOST_SCHEMA),
        doc="emulated hosts (network namespaces) the processes can be placed in",
    ),
    "placement": opt("map", {}, item=Field("str"), doc="process name -> host, for included processes"),
    "dds_profile": opt("str", None, doc="Fast DDS profile template for processes in hosts"),
    "host_multicast": opt("bool", False, doc="whether the hosts' emulated switch forwards multicast"),
}


@dataclass(frozen=True)
class ProcessSpec:
    """One process of a launch set, resolved and ready to start."""

    name: str
    argv: tuple[str, ...]
    env: dict[str, str]
    cwd: str | None
    restart: str
    max_restarts: int
    restart_delay_s: float
    required: bool
    on_exit: str
    startup_s: float
    on_refusal: str = "continue"
    wait_for_path: str | None = None
    wait_timeout_s: float = 30.0
    host: str | None = None
    nice: int = 0


@dataclass(frozen=True)
class LaunchSet:
    name: str
    source: str
    grace_period_s: float
    processes: tuple[ProcessSpec, ...] = field(default_factory=tuple)
    hosts: tuple[HostSpec, ...] = field(default_factory=tuple)
    dds_profile: str | None = None
    host_multicast: bool = False

    def __post_init__(self) -> None:
        if sum(p.on_exit == "shutdown" for p in self.processes) > 1:
            raise ConfigError(self.source, "processes", "at most one process may have on_exit: shutdown")


def _expand(text: str, variables: dict[str, str], source: str, key: str) -> str:
    def sub(match: re.Match[str]) -> str:
        var, default = match.group(1), match.group(2)
        if var in variables:
            return variables[var]
        if default is not None:
            return default
        raise ConfigError(source, key, f"${{{var}}} is not set in the environment or the launch set")

    return _VAR.sub(sub, text)


def _resolve_executable(executable: str, source: str, key: str) -> str:
    if executable == "python":
        return sys.executable
    if "/" in executable:
        path = Path(executable)
        if not (path.is_file() and os.access(path, os.X_OK)):
            raise ConfigError(source, key, f"{executable} is not an executable file")
        return str(path)
    # The venv's own scripts first, so a launch set works without activating the venv.
    venv_bin = str(Path(sys.executable).parent)
    found = shutil.which(executable, path=os.pathsep.join([venv_bin, os.environ.get("PATH", "")]))
    if found is None:
        raise ConfigError(source, key, f"executable {executable!r} not found in {venv_bin} or PATH")
    return found


def _ros_value(value: Any) -> str:
    # ROS parameter values on the command line are YAML; flow style keeps lists on one line.
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix("...").strip()


def load_launch_set(
    path: str | Path, base_env: dict[str, str] | None = None, _including: tuple[Path, ...] = ()
) -> LaunchSet:
    """Load and fully resolve a launch set; raise :class:`ConfigError` on any problem."""
    path = Path(path)
    source = str(path)
    data = validate(load_yaml(path), LAUNCH_SET_SCHEMA, source=source)
    if not data["processes"] and not data["include"]:
        raise ConfigError(source, "processes", "no processes and nothing included")
    if _including:
        for key in ("hosts", "placement", "dds_profile", "host_multicast"):
            if data[key]:
                raise ConfigError(
                    source,
                    key,
                    f"only the top-level launch set may declare {key} "
                    f"(this set is included by {_including[-1]})",
                )
    base = dict(os.environ if base_env is None else base_env)
    base.pop("LAUNCH_DIR", None)
    set_env = {
        k: _expand(str(v), {**base, "LAUNCH_DIR": str(path.resolve().parent)}, source, f"env.{k}")
        for k, v in data["env"].items()
    }

    specs: list[ProcessSpec] = []
    for i, name in enumerate(data["include"]):
        included = (path.resolve().parent / name).resolve()
        if not included.is_file():
            raise ConfigError(source, f"include[{i}]", f"no launch set at {included}")
        if included in _including or included == path.resolve():
            raise ConfigError(source, f"include[{i}]", f"{name} includes itself")
        # The including set's environment is visible to, and given to, what it includes.
        inner = load_launch_set(included, {**base, **set_env}, (*_including, path.resolve()))
        specs += [dataclasses.replace(spec, env={**set_env, **spec.env}) for spec in inner.processes]
    base["LAUNCH_DIR"] = str(path.resolve().parent)
    seen = {spec.name for spec in specs}
    for i, proc in enumerate(data["processes"]):
        key = f"processes[{i}]"
        if proc["name"] in seen:  # also a name an included set uses
            raise ConfigError(source, f"{key}.name", f"duplicate process name {proc['name']!r}")
        seen.add(proc["name"])
        variables = {**base, **set_env}
        proc_env = {k: _expand(str(v), variables, source, f"{key}.env.{k}") for k, v in proc["env"].items()}
        variables.update(proc_env)
        executable = _resolve_executable(
            _expand(proc["executable"], variables, source, f"{key}.executable"), source, f"{key}.executable"
        )
        argv = [executable] + [
            _expand(str(a), variables, source, f"{key}.args[{j}]") for j, a in enumerate(proc["args"])
        ]
        if proc["node_name"] or proc["parameters"]:
            argv.append("--ros-args")
            if proc["node_name"]:
                argv += ["-r", f"__node:={proc['node_name']}"]
            for pname, pvalue in proc["parameters"].items():
                argv += ["-p", f"{pname}:={_ros_value(pvalue)}"]
        cwd = proc["cwd"] and _expand(proc["cwd"], variables, source, f"{key}.cwd")
        if cwd and not Path(cwd).is_dir():
            raise ConfigError(source, f"{key}.cwd", f"{cwd} is not a directory")
        specs.append(
            ProcessSpec(
                name=proc["name"],
                argv=tuple(argv),
                env={**set_env, **proc_env},
                cwd=cwd,
                restart=proc["restart"],
                max_restarts=proc["max_restarts"],
                restart_delay_s=proc["restart_delay_s"],
                required=proc["required"],
                on_exit=proc["on_exit"],
                on_refusal=proc["on_refusal"],
                wait_for_path=proc["wait_for_path"]
                and _expand(proc["wait_for_path"], variables, source, f"{key}.wait_for_path"),
                wait_timeout_s=proc["wait_timeout_s"],
                startup_s=proc["startup_s"],
                host=proc["host"],
                nice=proc["nice"],
            )
        )
    if _including:
        return LaunchSet(
            name=data["name"] or path.stem,
            source=source,
            grace_period_s=data["grace_period_s"],
            processes=tuple(specs),
        )
    hosts = _hosts(data, source)
    specs = _place(specs, data["placement"], hosts, source)
    dds_profile = None
    if hosts:
        dds_profile = str(DEFAULT_PROFILE)
        if data["dds_profile"]:
            expanded = Path(_expand(data["dds_profile"], base, source, "dds_profile"))
            dds_profile = str(expanded if expanded.is_absolute() else path.resolve().parent / expanded)
        if not Path(dds_profile).is_file():
            raise ConfigError(source, "dds_profile", f"no Fast DDS profile at {dds_profile}")
    return LaunchSet(
        name=data["name"] or path.stem,
        source=source,
        grace_period_s=data["grace_period_s"],
        processes=tuple(specs),
        hosts=hosts,
        dds_profile=dds_profile,
        host_multicast=data["host_multicast"],
    )


def _hosts(data: dict[str, Any], source: str) -> tuple[HostSpec, ...]:
    hosts = tuple(HostSpec(h["name"], h["address"], tuple(h["extra_addresses"])) for h in data["hosts"])
    names = [h.name for h in hosts]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ConfigError(source, f"hosts[{i}].name", f"duplicate host name {name!r}")
    try:
        check_addresses(hosts)
    except HostsError as exc:
        raise ConfigError(source, "hosts", str(exc)) from None
    return hosts


def _place(
    specs: list[ProcessSpec], placement: dict[str, str], hosts: tuple[HostSpec, ...], source: str
) -> list[ProcessSpec]:
    """Apply ``placement`` and check that every host a process names is declared."""
    names = {spec.name for spec in specs}
    declared = [h.name for h in hosts]
    undeclared = f"declared under hosts (hosts: {', '.join(declared) or 'none'})"
    for process, host in placement.items():
        if process not in names:
            raise ConfigError(source, f"placement.{process}", f"no process {process!r} in this set")
        if host not in declared:
            raise ConfigError(source, f"placement.{process}", f"no host {host!r} {undeclared}")
    placed = []
    for i, spec in enumerate(specs):
        placed_host = placement.get(spec.name, spec.host)
        if spec.host and placed_host != spec.host:
            raise ConfigError(
                source, f"placement.{spec.name}", f"{spec.name} already runs on host {spec.host!r}"
            )
        if placed_host and placed_host not in declared:
            raise ConfigError(source, f"processes[{i}].host", f"no host {placed_host!r} {undeclared}")
        placed.append(dataclasses.replace(spec, host=placed_host))
    return placed
