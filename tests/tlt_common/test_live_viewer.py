"""tlt-live-viewer (tlt_common.live_viewer): its page decodes ROS 2 messages from CDR with the
ros2msg schema the bridge advertises (run under Node.js, checked against rclpy's own serializer),
and its server hands out the page, three.js and the bridge's port."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import threading
import urllib.request
from collections.abc import Iterator

import numpy as np
import pytest
from rclpy.serialization import serialize_message
from visualization_msgs.msg import Marker, MarkerArray

from tlt_common.live_viewer import server
from tlt_common.live_viewer.server import WEB_DIR, LiveViewerServer, MissingThreeJs
from tlt_common.recording.message_definitions import MessageDefinitionSource
from tlt_common.ros.transform_messages import tf_message


def _node(script: str, stdin: str = "") -> str:
    """What Node.js prints running the ES module ``script`` beside the page's modules."""
    node = shutil.which("node")
    assert node, "Node.js is not installed (it comes with npm, which scripts/setup.sh needs)"
    done = subprocess.run(
        [node, "--input-type=module", "-e", script],
        input=stdin,
        capture_output=True,
        text=True,
        cwd=WEB_DIR,
        timeout=30,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def _decode_in_node(type_name: str, messages: list[bytes]) -> list[dict]:
    """The page's decoder, run by Node.js on ``messages`` of ``type_name``."""
    script = (
        'import { cdrDecoder } from "./ros2msg_cdr.js";\n'
        'import { readFileSync } from "node:fs";\n'
        'const input = JSON.parse(readFileSync(0, "utf8"));\n'
        "const decode = cdrDecoder(input.name, input.schema);\n"
        "const out = input.messages.map((hex) => decode(Uint8Array.from(Buffer.from(hex, 'hex'))));\n"
        "process.stdout.write(JSON.stringify(out, (k, v) => (v instanceof Uint8Array ? [...v] : v)));\n"
    )
    schema = MessageDefinitionSource().full_text(type_name)
    payload = json.dumps({"name": type_name, "schema": schema, "messages": [m.hex() for m in messages]})
    return json.loads(_node(script, payload))


def test_the_page_decodes_a_tf_message_as_rclpy_wrote_it():
    poses = {
        "ars_x/link_1": (np.array([0.5, -1.25, 2.0]), np.array([[0, -1.0, 0], [1.0, 0, 0], [0, 0, 1.0]])),
        "part/vertical_dispenser/3": (np.array([-3.0, 0.001, 7.5]), np.eye(3)),
    }
    sent = tf_message("lifter", poses, 12.75)
    (got,) = _decode_in_node("tf2_msgs/msg/TFMessage", [serialize_message(sent)])
    assert len(got["transforms"]) == 2
    for want, have in zip(sent.transforms, got["transforms"], strict=True):
        assert have["header"] == {"stamp": {"sec": 12, "nanosec": 750_000_000}, "frame_id": "lifter"}
        assert have["child_frame_id"] == want.child_frame_id
        t, q = want.transform.translation, want.transform.rotation
        assert have["transform"]["translation"] == {"x": t.x, "y": t.y, "z": t.z}
        assert have["transform"]["rotation"] == {"x": q.x, "y": q.y, "z": q.z, "w": q.w}


def test_the_page_decodes_every_field_of_a_marker_array():
    """Strings of several lengths (the fields after them start at several alignments), sequences
    of structures, float32 colours, bytes and bools: a field misread shifts every one after it."""
    cube = Marker(ns="payload", id=3, type=Marker.CUBE, action=Marker.ADD, frame_locked=True)
    cube.header.frame_id = "payload"
    cube.header.stamp.sec, cube.header.stamp.nanosec = 7, 5
    cube.pose.position.x, cube.pose.orientation.w = 1.5, 1.0
    cube.scale.x, cube.scale.y, cube.scale.z = 0.1, 0.2, 0.3
    cube.color.r, cube.color.a = 0.25, 1.0
    points = Marker(ns="vision/zed_1", id=0, type=Marker.SPHERE_LIST, text="end_fitting_0")
    points.header.frame_id = "zed_1_optical"
    points.points = [type(cube.pose.position)(x=float(i), y=-float(i), z=0.5) for i in range(3)]
    points.colors = [type(cube.color)(r=0.0, g=1.0, b=0.0, a=0.5)] * 3
    points.mesh_file.filename = "m.stl"
    points.mesh_file.data = bytes([1, 2, 250])
    points.mesh_use_embedded_materials = True
    points.texture.format = "png"
    clear = Marker(action=Marker.DELETEALL)
    sent = MarkerArray(markers=[clear, cube, points])
    (got,) = _decode_in_node("visualization_msgs/msg/MarkerArray", [serialize_message(sent)])
    assert [m["action"] for m in got["markers"]] == [Marker.DELETEALL, Marker.ADD, Marker.ADD]
    c = got["markers"][1]
    assert (c["ns"], c["id"], c["type"], c["frame_locked"]) == ("payload", 3, Marker.CUBE, True)
    assert c["header"] == {"stamp": {"sec": 7, "nanosec": 5}, "frame_id": "payload"}
    assert c["pose"]["position"] == {"x": 1.5, "y": 0.0, "z": 0.0}
    assert c["scale"] == {"x": 0.1, "y": 0.2, "z": 0.3}
    assert c["color"] == {"r": 0.25, "g": 0.0, "b": 0.0, "a": 1.0}
    p = got["markers"][2]
    assert p["points"] == [{"x": float(i), "y": -float(i), "z": 0.5} for i in range(3)]
    assert p["colors"] == [{"r": 0.0, "g": 1.0, "b": 0.0, "a": 0.5}] * 3
    assert p["text"] == "end_fitting_0" and p["texture"]["format"] == "png"
    assert p["mesh_file"] == {"filename": "m.stl", "data": [1, 2, 250]}
    assert p["mesh_use_embedded_materials"] is True


@pytest.fixture
def viewer() -> Iterator[LiveViewerServer]:
    running = LiveViewerServer(port=0, bridge_port=4321)
    threading.Thread(target=running.serve_forever, daemon=True).start()
    yield running
    running.shutdown()
    running.server_close()


def _get(url: str) -> tuple[str, bytes]:
    with urllib.request.urlopen(url, timeout=10) as reply:
        return reply.headers["Content-Type"], reply.read()


def test_the_server_hands_out_the_page_three_js_and_the_bridge_port(viewer):
    assert re.fullmatch(r"http://127\.0\.0\.1:\d+/", viewer.address)
    kind, page = _get(viewer.address)
    assert kind.startswith("text/html") and b'<script type="module" src="viewer.js">' in page
    kind, config = _get(viewer.address + "config.json")
    assert kind == "application/json" and json.loads(config) == {"bridgePort": 4321}
    # Every module the page imports is served, as JavaScript (browsers refuse modules otherwise).
    importmap = re.search(rb'<script type="importmap">(.*?)</script>', page, re.S)
    imports = json.loads(importmap.group(1))["imports"]
    for url in [imports["three"], imports["three/addons/"] + "controls/OrbitControls.js", "viewer.js"]:
        kind, body = _get(viewer.address + url.removeprefix("./"))
        assert "javascript" in kind and body, url


def test_without_three_js_the_viewer_says_what_to_run(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(server, "THREE_MODULE", tmp_path / "three.module.js")
    with pytest.raises(MissingThreeJs, match=r"scripts/setup\.sh"):
        LiveViewerServer(port=0)
    assert server.main(["--port", "0"]) == 1
    assert "three.js is not installed" in capsys.readouterr().err


def test_the_page_subscribes_to_its_topics_and_asks_again_for_a_silent_latched_one():
    """foxglove_client.js against a stand-in WebSocket: it offers the foxglove.sdk.v1 subprotocol,
    subscribes to the topics it has handlers for, renews the subscription of a latched topic
    until a message comes, and decodes that message with the advertised schema."""
    script = """
import { FoxgloveClient } from "./foxglove_client.js";
class StandIn {
  static OPEN = 1;
  constructor(url, protocols) {
    Object.assign(this, { url, protocols, sent: [], readyState: 1 });
    StandIn.last = this;
  }
  send(text) { this.sent.push(JSON.parse(text)); }
}
globalThis.WebSocket = StandIn;
const sleep = (ms) => new Promise((done) => setTimeout(done, ms));
const got = [];
const handlers = { "/latched": (m) => got.push(m), "/live": () => {} };
new FoxgloveClient("ws://127.0.0.1:1", handlers, ["/latched"], () => {}, 40);
const ws = StandIn.last;
const channel = (id, topic) => ({ id, topic, encoding: "cdr", schemaName: "std_msgs/msg/String",
  schema: "string data", schemaEncoding: "ros2msg" });
ws.onmessage({ data: JSON.stringify({ op: "advertise",
  channels: [channel(4, "/latched"), channel(5, "/live"), channel(6, "/other")] }) });
await sleep(100);
const subscriptions = ws.sent.filter((op) => op.op === "subscribe");
const last = subscriptions.at(-1).subscriptions[0].id;
const frame = new Uint8Array([1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 3, 0, 0, 0, 104, 105, 0]);
new DataView(frame.buffer).setUint32(1, last, true);
ws.onmessage({ data: frame.buffer });
const sentBefore = ws.sent.length;
await sleep(120);
const after = ws.sent.length - sentBefore;
console.log(JSON.stringify({ protocols: ws.protocols, sent: ws.sent, got, after }));
"""
    out = json.loads(_node(script))
    assert out["protocols"] == ["foxglove.sdk.v1"]
    first, *renewals = out["sent"]
    assert first["op"] == "subscribe"
    assert sorted(s["channelId"] for s in first["subscriptions"]) == [4, 5]  # not /other
    latched_id = next(s["id"] for s in first["subscriptions"] if s["channelId"] == 4)
    assert len(renewals) >= 2 and len(renewals) % 2 == 0
    for unsubscribe, subscribe in zip(renewals[::2], renewals[1::2], strict=True):
        assert unsubscribe == {"op": "unsubscribe", "subscriptionIds": [latched_id]}
        assert subscribe["op"] == "subscribe" and subscribe["subscriptions"][0]["channelId"] == 4
        latched_id = subscribe["subscriptions"][0]["id"]
    assert out["got"] == [{"data": "hi"}]
    assert out["after"] == 0, "asked again after the latched message came"
