// The TLT live viewer (docs/live-view.md): the EDU, the tower and the arms in three.js, live from
// tlt-live-bridge over Foxglove's WebSocket protocol.
//
// - /robot_description: the URDF's link visuals (boxes, cylinders, spheres), each in its link's frame;
// - /tf_static and /tf: one three.js group per frame, under its parent's, at the transform's pose,
//   so a link moves when its joint does; a frame not yet joined to "world" stays hidden;
// - /twin/markers and /vision/markers (visualization_msgs/MarkerArray): cubes, spheres, cylinders
//   and sphere lists in their frames (the payload and the parts, vision's keypoints).
//
// The page asks for the bridge at ?ws=ws://host:port, else on its own host at the port config.json
// names (tlt-live-viewer's --bridge-port), else 8765. Its counts are on window.tltViewer.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import { FoxgloveClient } from "./foxglove_client.js";

const WORLD = "world";
const CUBE = 1, SPHERE = 2, CYLINDER = 3, CUBE_LIST = 6, SPHERE_LIST = 7, ADD = 0, DELETEALL = 3;
const MARKER_TOPICS = ["/twin/markers", "/vision/markers"];

// --- scene ---------------------------------------------------------------------------------------
const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1d2127);
const camera = new THREE.PerspectiveCamera(45, 1, 0.05, 200);
camera.up.set(0, 0, 1); // ROS frames: z up
camera.position.set(6, -6, 4.5);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0, 1.5);
let cameraFitted = false;
controls.addEventListener("start", () => (cameraFitted = true)); // the user's view wins
scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 2.0);
sun.position.set(4, -6, 10);
scene.add(sun);
const grid = new THREE.GridHelper(10, 20, 0x555b66, 0x353a42);
grid.rotation.x = Math.PI / 2; // three's grid lies in x-z; the floor is x-y
scene.add(grid);

function resize() {
  renderer.setSize(window.innerWidth, window.innerHeight);
  camera.aspect = window.innerWidth / window.innerHeight;
  camera.updateProjectionMatrix();
}
window.addEventListener("resize", resize);
resize();

// --- frames --------------------------------------------------------------------------------------
const world = new THREE.Group();
scene.add(world);
const detached = new THREE.Group(); // frames whose parent chain does not reach world yet
detached.visible = false;
scene.add(detached);
const frames = new Map([[WORLD, world]]);
let tfMessages = 0;
let simTime = 0;

function frame(name) {
  let group = frames.get(name);
  if (!group) {
    group = new THREE.Group();
    group.name = name;
    frames.set(name, group);
    detached.add(group);
  }
  return group;
}

function applyTransforms(message) {
  for (const t of message.transforms) {
    const parent = frame(t.header.frame_id);
    const child = frame(t.child_frame_id);
    if (child.parent !== parent) parent.add(child);
    const p = t.transform.translation;
    const q = t.transform.rotation;
    child.position.set(p.x, p.y, p.z);
    child.quaternion.set(q.x, q.y, q.z, q.w);
    simTime = Math.max(simTime, t.header.stamp.sec + t.header.stamp.nanosec * 1e-9);
  }
}

// --- shapes --------------------------------------------------------------------------------------
const unitBox = new THREE.BoxGeometry(1, 1, 1);
const unitSphere = new THREE.SphereGeometry(0.5, 20, 14);
const unitCylinder = new THREE.CylinderGeometry(0.5, 0.5, 1, 24).rotateX(Math.PI / 2); // along z, as ROS's
const materials = new Map();

function material(r, g, b, a) {
  const key = [r, g, b, a].map((v) => v.toFixed(3)).join(",");
  if (!materials.has(key)) {
    materials.set(
      key,
      new THREE.MeshStandardMaterial({
        color: new THREE.Color().setRGB(r, g, b, THREE.SRGBColorSpace),
        transparent: a < 1,
        opacity: a,
        roughness: 0.7,
        metalness: 0.1,
      }),
    );
  }
  return materials.get(key);
}

function shape(geometry, scale, mat) {
  const mesh = new THREE.Mesh(geometry, mat);
  mesh.scale.set(scale[0], scale[1], scale[2]);
  return mesh;
}

// --- the robot description -----------------------------------------------------------------------
const robotVisuals = [];

function numbers(text, fallback) {
  return text ? text.trim().split(/\s+/).map(Number) : fallback;
}

function urdfVisual(visual) {
  const geometry = visual.querySelector("geometry > *");
  const rgba = numbers(visual.querySelector("material > color")?.getAttribute("rgba"), [0.7, 0.7, 0.7, 1]);
  const mat = material(...rgba);
  let mesh;
  if (geometry.tagName === "box") {
    mesh = shape(unitBox, numbers(geometry.getAttribute("size")), mat);
  } else if (geometry.tagName === "sphere") {
    const d = 2 * Number(geometry.getAttribute("radius"));
    mesh = shape(unitSphere, [d, d, d], mat);
  } else if (geometry.tagName === "cylinder") {
    const d = 2 * Number(geometry.getAttribute("radius"));
    mesh = shape(unitCylinder, [d, d, Number(geometry.getAttribute("length"))], mat);
  } else {
    return null; // meshes: the project's URDF has none
  }
  const origin = visual.querySelector("origin");
  const [x, y, z] = numbers(origin?.getAttribute("xyz"), [0, 0, 0]);
  const [roll, pitch, yaw] = numbers(origin?.getAttribute("rpy"), [0, 0, 0]);
  mesh.position.set(x, y, z);
  mesh.rotation.set(roll, pitch, yaw, "ZYX"); // URDF's fixed-axis roll, pitch, yaw: Rz Ry Rx
  return mesh;
}

function showRobot(message) {
  for (const mesh of robotVisuals.splice(0)) mesh.removeFromParent();
  const doc = new DOMParser().parseFromString(message.data, "application/xml");
  for (const link of doc.querySelectorAll("robot > link")) {
    for (const visual of link.querySelectorAll(":scope > visual")) {
      const mesh = urdfVisual(visual);
      if (!mesh) continue;
      frame(link.getAttribute("name")).add(mesh);
      robotVisuals.push(mesh);
    }
  }
}

// --- markers -------------------------------------------------------------------------------------
const markers = new Map(MARKER_TOPICS.map((topic) => [topic, new Map()])); // topic -> "ns/id" -> object

function markerObject(m) {
  const c = m.color;
  const mat = material(c.r, c.g, c.b, c.a);
  const scale = [m.scale.x, m.scale.y, m.scale.z];
  let object;
  if (m.type === CUBE) object = shape(unitBox, scale, mat);
  else if (m.type === SPHERE) object = shape(unitSphere, scale, mat);
  else if (m.type === CYLINDER) object = shape(unitCylinder, scale, mat);
  else if (m.type === SPHERE_LIST || m.type === CUBE_LIST) {
    object = new THREE.Group();
    m.points.forEach((p, i) => {
      const pc = m.colors[i] || c;
      const item = shape(m.type === CUBE_LIST ? unitBox : unitSphere, scale, material(pc.r, pc.g, pc.b, pc.a));
      item.position.set(p.x, p.y, p.z);
      object.add(item);
    });
  } else {
    return null; // text, lines, meshes: not drawn here
  }
  const pose = new THREE.Group();
  pose.position.set(m.pose.position.x, m.pose.position.y, m.pose.position.z);
  const q = m.pose.orientation;
  pose.quaternion.set(q.x, q.y, q.z, q.w);
  pose.add(object);
  return pose;
}

function applyMarkers(topic, message) {
  const shown = markers.get(topic);
  for (const m of message.markers) {
    if (m.action === DELETEALL) {
      for (const object of shown.values()) object.removeFromParent();
      shown.clear();
      continue;
    }
    const key = `${m.ns}/${m.id}`;
    shown.get(key)?.removeFromParent();
    shown.delete(key);
    if (m.action !== ADD) continue; // DELETE: gone above (ADD is also MODIFY: replaced)
    const object = markerObject(m);
    if (!object) continue;
    frame(m.header.frame_id).add(object);
    shown.set(key, object);
  }
}

// --- the view ------------------------------------------------------------------------------------
const status = document.getElementById("status");
let connection = "";

function fitCamera() {
  const box = new THREE.Box3().setFromObject(world);
  if (box.isEmpty()) return;
  const center = box.getCenter(new THREE.Vector3());
  const radius = box.getSize(new THREE.Vector3()).length() / 2;
  // The bounding sphere of a wide, flat scene fills a view from above at well under its radius.
  const distance = (radius / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2))) * 0.62;
  const direction = new THREE.Vector3(1, -1.1, 0.75).normalize();
  camera.position.copy(center).addScaledVector(direction, distance);
  controls.target.copy(center);
  controls.update();
}

function stats() {
  let shownMarkers = 0;
  for (const shown of markers.values()) shownMarkers += shown.size;
  let visible = 0;
  world.traverse((o) => (visible += o.isMesh ? 1 : 0));
  return { connection, frames: frames.size, robotVisuals: robotVisuals.length, markers: shownMarkers,
    meshesInWorld: visible, tfMessages, simTime, received: { ...client.received },
    resubscribed: client.resubscribed, viewFitted: cameraFitted,
    errors: client.errors.slice(-5) };
}

const params = new URLSearchParams(window.location.search);
const config = await fetch("config.json").then((r) => (r.ok ? r.json() : {})).catch(() => ({}));
const host = window.location.hostname || "127.0.0.1";
const bridge = params.get("ws") || `ws://${host}:${config.bridgePort || 8765}`;
const handlers = {
  "/robot_description": showRobot,
  "/tf_static": applyTransforms,
  "/tf": (message) => {
    tfMessages += 1;
    applyTransforms(message);
  },
};
for (const topic of MARKER_TOPICS) handlers[topic] = (message) => applyMarkers(topic, message);
const latched = ["/robot_description", "/tf_static", "/twin/markers"];
const client = new FoxgloveClient(bridge, handlers, latched, (text) => (connection = text));
// A frame's position in world as the page draws it (null: not joined to world).
function worldPosition(name) {
  const group = frames.get(name);
  let joined = group;
  while (joined && joined !== world) joined = joined.parent;
  return joined ? group.getWorldPosition(new THREE.Vector3()).toArray() : null;
}
window.tltViewer = { stats, fitCamera, worldPosition };

let lastFit = 0;
let fitsWithRobot = 0;
renderer.setAnimationLoop((now) => {
  // Fit the view to what is shown as the EDU's frames and parts arrive, a few times once the robot
  // is there, and never after the user moved it.
  if (!cameraFitted && now - lastFit > 500) {
    lastFit = now;
    fitCamera();
    if (robotVisuals.length && tfMessages) cameraFitted = ++fitsWithRobot >= 6;
  }
  controls.update();
  renderer.render(scene, camera);
  const s = stats();
  status.textContent = `${s.connection} · ${s.frames} frames · ${s.robotVisuals} robot shapes · ` +
    `${s.markers} markers · /tf ${s.tfMessages} · sim ${s.simTime.toFixed(1)} s` +
    (s.errors.length ? ` · ${s.errors.at(-1)}` : "");
});
