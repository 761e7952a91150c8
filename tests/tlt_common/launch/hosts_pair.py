"""An AddMember action server and a scripted client, for the tests that run them in different
emulated hosts. Run as ``hosts_pair.py server`` or ``hosts_pair.py client [HOLD_S]``.

The server holds each goal for the seconds its ``position`` field names (``hold:4``), publishing
feedback meanwhile, then succeeds with ``placed <member_id>``.

The client prints what it sees, one event per line, and exits by itself:
  ``server found`` / ``server lost``   the action server appears in / leaves the ROS graph
  ``result <id> success=<b> reason=<r>``
It sends ``m0`` (no hold: the round trip), then ``m1`` (held HOLD_S, default 0: the goal that is in
flight when the test cuts a link). If the server is lost while ``m1`` is pending, the client keeps
its goal handle and, once the server is found again, asks for ``m1``'s result again (every 2 s,
since a request sent just as discovery completes may be dropped) and then sends ``m2``. It exits 0
after ``m2``'s result, or 3 after 60 s.
"""

from __future__ import annotations

import sys
import time

import rclpy
from rclpy.action import ActionServer
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from tlt_interfaces.action import AddMember

from tlt_common.ros.action_client import SerialisedActionClient

ACTION = "hosts/add_member"


def serve() -> None:
    node = Node("hosts_server")

    def execute(handle):
        hold = float(handle.request.position.removeprefix("hold:") or 0)
        end = time.monotonic() + hold
        while time.monotonic() < end:
            handle.publish_feedback(AddMember.Feedback(step="holding", progress=0.0))
            time.sleep(0.1)
        handle.succeed()
        print(f"server finished {handle.request.member_id}", flush=True)
        return AddMember.Result(success=True, reason=f"placed {handle.request.member_id}")

    def accepted(handle):
        print(f"server accepted {handle.request.member_id}", flush=True)
        handle.execute()

    ActionServer(node, AddMember, ACTION, execute, handle_accepted_callback=accepted)
    print("server up", flush=True)
    executor = MultiThreadedExecutor(num_threads=3)
    executor.add_node(node)
    executor.spin()


class Client:
    def __init__(self, hold_s: float) -> None:
        self.node = Node("hosts_client")
        self.action = SerialisedActionClient(self.node, AddMember, ACTION)
        self.hold_s = hold_s
        self.present = False
        self.lost_while_pending = False
        self.handles: dict[str, object] = {}
        self.results: dict[str, object] = {}
        self.sent: set[str] = set()
        self.last_ask = 0.0
        self.started = time.monotonic()
        self.node.create_timer(0.1, self.tick)

    def tick(self) -> None:
        if time.monotonic() - self.started > 60:
            print("client gives up", flush=True)
            raise SystemExit(3)
        ready = self.action.server_is_ready()
        if ready != self.present:
            self.present = ready
            print("server found" if ready else "server lost", flush=True)
            if not ready and "m1" in self.sent and "m1" not in self.results:
                self.lost_while_pending = True
        if not ready:
            return
        if "m0" not in self.sent:
            self.send("m0", 0.0)
        elif "m0" in self.results and "m1" not in self.sent:
            self.send("m1", self.hold_s)
        elif "m1" not in self.results and self.lost_while_pending and "m1" in self.handles:
            if time.monotonic() - self.last_ask > 2.0:
                self.last_ask = time.monotonic()
                print("asking again for m1", flush=True)
                self.handles["m1"].get_result_async().add_done_callback(lambda f: self.on_result("m1", f))
        elif "m1" in self.results and "m2" not in self.sent:
            self.send("m2", 0.0)
        elif "m2" in self.results:
            raise SystemExit(0)

    def send(self, member: str, hold_s: float) -> None:
        self.sent.add(member)
        goal = AddMember.Goal(
            kind=AddMember.Goal.KIND_VERTICAL, bay=1, member_id=member, position=f"hold:{hold_s}"
        )
        self.action.send_goal_async(goal).add_done_callback(lambda f: self.on_accepted(member, f))

    def on_accepted(self, member: str, future) -> None:
        handle = future.result()
        print(f"goal {member} {'accepted' if handle.accepted else 'rejected'}", flush=True)
        self.handles[member] = handle
        handle.get_result_async().add_done_callback(lambda f: self.on_result(member, f))

    def on_result(self, member: str, future) -> None:
        if member in self.results:
            return
        result = future.result().result
        self.results[member] = result
        print(f"result {member} success={result.success} reason={result.reason}", flush=True)


def client(hold_s: float) -> int:
    node = Client(hold_s).node
    try:
        rclpy.spin(node)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


if __name__ == "__main__":
    rclpy.init()
    code = 0
    try:
        if sys.argv[1] == "server":
            serve()
        else:
            code = client(float(sys.argv[2]) if len(sys.argv) > 2 else 0.0)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    sys.exit(code)
