// The replay page's script (src/viewer/page/viewer.js, inlined by src/viewer/mod.rs): draws the
// recorded bodies with three.js, plays them, and plots the tracking errors under the view. A
// goal-task replay (data.goals) draws the goal on the ground and counts the goals reached
// instead: its reference track is its simulated one, and it has no tracking errors to show.
// A mocap file imported on the fly (data.source_skeleton) also draws the file's skeleton, as
// retargeting scaled and placed it, as a stick figure over the character (or shifted sideways).
// World frame: MuJoCo's, Z up. Quaternions in the data are (w, x, y, z); three.js wants x, y, z, w.

const data = JSON.parse(document.getElementById("recording-data").textContent);
const params = new URLSearchParams(location.hash.slice(1));
const $ = (id) => document.getElementById(id);

// three.js's ES modules without a bundler or a fetch: each file becomes a blob: URL, and the
// module's import of "./three.core.min.js" is pointed at the core's URL.
async function loadThree() {
  const blobUrl = (text) => URL.createObjectURL(new Blob([text], { type: "text/javascript" }));
  const core = blobUrl($("three-core").textContent);
  const module = $("three-module").textContent.split('"./three.core.min.js"').join(JSON.stringify(core));
  return import(blobUrl(module));
}

// Base64 of little-endian f32 values (every browser's platform is little-endian).
function floats(text) {
  const binary = atob(text);
  const bytes = new Uint8Array(binary.length);
  for (let i = 0; i < binary.length; i++) bytes[i] = binary.charCodeAt(i);
  return new Float32Array(bytes.buffer);
}

const COLORS = { simulated: 0xd9732f, reference: 0x3b7dd8, goal: 0x2e9d57, source: 0xc2188b };
const bodyCount = data.bodies.length;
const tracks = {
  reference: { pos: floats(data.reference.pos), quat: floats(data.reference.quat) },
  simulated: data.simulated && { pos: floats(data.simulated.pos), quat: floats(data.simulated.quat) },
};
const sourceSkeleton = data.source_skeleton && {
  names: data.source_skeleton.names,
  parents: data.source_skeleton.parents,
  pos: floats(data.source_skeleton.pos),
};
const goals = data.goals && { position: floats(data.goals.position), reached: floats(data.goals.reached) };
// A goal replay's errors are against its own poses (all zero): the page shows the goals instead.
const errors = !goals && data.errors && Object.fromEntries(Object.entries(data.errors).map(([k, v]) => [k, floats(v)]));
// The character drawn solid: the simulated one, or the reference for a clip alone.
const solidTrack = tracks.simulated ? "simulated" : "reference";

let THREE;
try {
  THREE = await loadThree();
} catch (e) {
  $("status").textContent = "could not load three.js: " + e;
  throw e;
}

const canvas = $("scene");
let renderer;
try {
  renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
} catch (e) {
  $("status").textContent = "WebGL is not available in this browser: " + e.message;
  throw e;
}
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xe9edf2);
const camera = new THREE.PerspectiveCamera(40, 1, 0.05, 200);
camera.up.set(0, 0, 1);
scene.add(new THREE.HemisphereLight(0xffffff, 0x7d8a99, 2.2));
const sun = new THREE.DirectionalLight(0xffffff, 1.6);
sun.position.set(3, -4, 6);
scene.add(sun);
// A checkered floor of 1 m squares (a 2 x 2 texture repeated; lines of a GridHelper vanish in
// software WebGL, where the headless test and the screenshots render).
const checker = new THREE.DataTexture(new Uint8Array([
  226, 230, 235, 255, 205, 211, 219, 255,
  205, 211, 219, 255, 226, 230, 235, 255,
]), 2, 2);
checker.colorSpace = THREE.SRGBColorSpace;
checker.wrapS = checker.wrapT = THREE.RepeatWrapping;
checker.repeat.set(30, 30);
checker.magFilter = THREE.NearestFilter;
checker.minFilter = THREE.LinearMipmapLinearFilter;
checker.generateMipmaps = true;
checker.anisotropy = 8;
checker.needsUpdate = true;
const floor = new THREE.Mesh(new THREE.PlaneGeometry(60, 60), new THREE.MeshStandardMaterial({ map: checker, roughness: 1 }));
scene.add(floor);

function geometryOf(geom) {
  const [a, b, c] = geom.size;
  switch (geom.kind) {
    case "sphere": return new THREE.SphereGeometry(a, 24, 16);
    // three.js builds capsules and cylinders along +Y; MuJoCo's lie along the geom's +Z.
    case "capsule": return new THREE.CapsuleGeometry(a, 2 * b, 8, 16).rotateX(Math.PI / 2);
    case "cylinder": return new THREE.CylinderGeometry(a, a, 2 * b, 16).rotateX(Math.PI / 2);
    case "ellipsoid": return new THREE.SphereGeometry(1, 24, 16).scale(a, b, c);
    case "box": return new THREE.BoxGeometry(2 * a, 2 * b, 2 * c);
    default: throw new Error("unknown geom kind " + geom.kind);
  }
}

function buildCharacter(material) {
  const groups = data.bodies.map((name) => {
    const group = new THREE.Group();
    group.name = name;
    scene.add(group);
    return group;
  });
  for (const geom of data.geoms) {
    const mesh = new THREE.Mesh(geometryOf(geom), material);
    mesh.position.set(...geom.pos);
    mesh.quaternion.set(geom.quat[1], geom.quat[2], geom.quat[3], geom.quat[0]);
    groups[geom.body].add(mesh);
  }
  return groups;
}

const characters = {};
characters[solidTrack] = buildCharacter(new THREE.MeshStandardMaterial({ color: COLORS[solidTrack], roughness: 0.55 }));
if (tracks.simulated && !goals) {
  characters.reference = buildCharacter(new THREE.MeshStandardMaterial({
    color: COLORS.reference, roughness: 0.55, transparent: true, opacity: 0.32, depthWrite: false,
  }));
}

// The goal: a disc on the ground with a post above it, moved to each frame's goal.
let goalMarker = null;
if (goals) {
  const material = new THREE.MeshStandardMaterial({ color: COLORS.goal, roughness: 0.5 });
  goalMarker = new THREE.Group();
  goalMarker.name = "goal";
  const disc = new THREE.Mesh(new THREE.CylinderGeometry(0.25, 0.25, 0.02, 32).rotateX(Math.PI / 2), material);
  disc.position.z = 0.01;
  const post = new THREE.Mesh(new THREE.CylinderGeometry(0.03, 0.03, 1.2, 12).rotateX(Math.PI / 2), material);
  post.position.z = 0.6;
  const flag = new THREE.Mesh(new THREE.SphereGeometry(0.1, 16, 12), material);
  flag.position.z = 1.25;
  goalMarker.add(disc, post, flag);
  scene.add(goalMarker);
}

// The source skeleton: a sphere per joint and a thin cylinder per bone (joint to parent), drawn
// over the character (no depth test), in a group shifted sideways along the screen.
let sourceFigure = null;
if (sourceSkeleton) {
  const material = new THREE.MeshBasicMaterial({ color: COLORS.source, depthTest: false, transparent: true, opacity: 0.9 });
  const group = new THREE.Group();
  group.name = "source skeleton";
  group.renderOrder = 10;
  const jointGeometry = new THREE.SphereGeometry(0.022, 12, 8);
  // A unit-length cylinder along +Y, stretched from joint to parent each frame.
  const boneGeometry = new THREE.CylinderGeometry(0.008, 0.008, 1, 8).translate(0, 0.5, 0);
  const joints = sourceSkeleton.names.map(() => {
    const mesh = new THREE.Mesh(jointGeometry, material);
    mesh.renderOrder = 10;
    group.add(mesh);
    return mesh;
  });
  const bones = sourceSkeleton.parents.map((parent) => {
    if (parent < 0) return null;
    const mesh = new THREE.Mesh(boneGeometry, material);
    mesh.renderOrder = 10;
    group.add(mesh);
    return mesh;
  });
  scene.add(group);
  sourceFigure = { group, joints, bones, shift: 0 };
}

// --- state -------------------------------------------------------------------------------
const state = {
  episode: Math.min(Math.max(parseInt(params.get("episode") || "0", 10) || 0, 0), data.episodes.length - 1),
  frame: 0,
  playing: !params.has("frame") && !params.has("selftest"),
  speed: 1,
  playTime: 0,
  follow: true,
  target: new THREE.Vector3(0, 0, 0.9),
  orbit: { azimuth: -Math.PI / 2 + 0.35, elevation: parseFloat(params.get("elevation") || "0.28"), distance: 3.6 },
};
const episode = () => data.episodes[state.episode];

function placeCharacter(groups, track, row) {
  const { pos, quat } = tracks[track];
  for (let b = 0; b < bodyCount; b++) {
    const i = row * bodyCount + b;
    groups[b].position.set(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]);
    groups[b].quaternion.set(quat[4 * i + 1], quat[4 * i + 2], quat[4 * i + 3], quat[4 * i]);
  }
}

const UP_Y = new THREE.Vector3(0, 1, 0);
function placeSource(row) {
  const n = sourceSkeleton.names.length;
  const p = sourceSkeleton.pos;
  const at = (j) => new THREE.Vector3(p[3 * (row * n + j)], p[3 * (row * n + j) + 1], p[3 * (row * n + j) + 2]);
  sourceFigure.joints.forEach((mesh, j) => mesh.position.copy(at(j)));
  sourceFigure.bones.forEach((mesh, j) => {
    if (!mesh) return;
    const from = at(j);
    const to = at(sourceSkeleton.parents[j]);
    const span = to.clone().sub(from);
    const length = span.length();
    mesh.visible = length > 1e-6;
    if (!mesh.visible) return;
    mesh.position.copy(from);
    mesh.quaternion.setFromUnitVectors(UP_Y, span.divideScalar(length));
    mesh.scale.set(1, length, 1);
  });
}

// The source skeleton's sideways shift: along the screen's horizontal, on the ground.
function shiftSource() {
  if (!sourceFigure) return;
  const { azimuth } = state.orbit;
  sourceFigure.group.position.set(-Math.sin(azimuth), Math.cos(azimuth), 0).multiplyScalar(sourceFigure.shift);
}

function placeCamera() {
  const { azimuth, elevation, distance } = state.orbit;
  const offset = new THREE.Vector3(
    Math.cos(elevation) * Math.cos(azimuth), Math.cos(elevation) * Math.sin(azimuth), Math.sin(elevation),
  ).multiplyScalar(distance);
  camera.position.copy(state.target).add(offset);
  camera.lookAt(state.target);
}

let renderQueued = false;
function requestRender() {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(() => { renderQueued = false; render(); });
}
function render() {
  placeCamera();
  shiftSource();
  renderer.render(scene, camera);
}

function showFrame(frame) {
  const ep = episode();
  state.frame = Math.min(Math.max(frame, 0), ep.frames - 1);
  const row = ep.first_row + state.frame;
  for (const [track, groups] of Object.entries(characters)) placeCharacter(groups, track, row);
  if (sourceFigure) placeSource(row);
  if (state.follow) {
    const root = characters[solidTrack][0].position;
    state.target.set(root.x, root.y, 0.9);
  }
  if (goals) showGoal(ep, row);
  $("scrubber").value = String(state.frame);
  const t = state.frame * data.control_dt;
  $("time").textContent = `${t.toFixed(2)} s, frame ${state.frame} / ${ep.frames - 1}`;
  drawPlot();
  render();
}

function showGoal(ep, row) {
  const [gx, gy] = [goals.position[2 * row], goals.position[2 * row + 1]];
  goalMarker.position.set(gx, gy, 0);
  const root = characters[solidTrack][0].position;
  const reached = goals.reached[row];
  const total = goals.reached[ep.first_row + ep.frames - 1];
  $("goal-overlay").textContent = `goals reached: ${reached} of ${total}`;
  $("plot-readout").textContent = `frame ${state.frame}: goal at (${gx.toFixed(2)}, ${gy.toFixed(2)}) m, ` +
    `${Math.hypot(gx - root.x, gy - root.y).toFixed(2)} m from the root; ${reached} goals reached so far`;
}

// --- controls ------------------------------------------------------------------------------
function describeEpisode(ep, i) {
  if (goals) {
    const total = goals.reached[ep.first_row + ep.frames - 1];
    const span = `${((ep.frames - 1) * data.control_dt).toFixed(2)} s`;
    return ep.outcome === "failed"
      ? `episode ${i}: ${total} goals reached, then fell at frame ${ep.failed_frame} (${span})`
      : `episode ${i}: ${total} goals reached in ${span}`;
  }
  const start = `starts at ${ep.start_time_s.toFixed(2)} s of the clip`;
  switch (ep.outcome) {
    case "reference": return `the reference clip, ${ep.frames} frames at ${(1 / data.control_dt).toFixed(1)} Hz`;
    case "succeeded": return `episode ${i}: ${start}, succeeded`;
    case "completed": return `episode ${i}: ${start}, completed but drifted past the success bound`;
    default: {
      const at = ep.failed_frame == null ? "" : ` at frame ${ep.failed_frame} (${(ep.failed_frame * data.control_dt).toFixed(2)} s)`;
      return `episode ${i}: ${start}, failed${at}${ep.failure ? ": " + ep.failure : ""}`;
    }
  }
}

function selectEpisode(i) {
  state.episode = i;
  state.playTime = 0;
  $("scrubber").max = String(episode().frames - 1);
  $("episode").value = String(i);
  $("episode-info").textContent = describeEpisode(episode(), i);
  showFrame(0);
}

function setPlaying(playing) {
  state.playing = playing;
  $("play").innerHTML = playing ? "&#10074;&#10074;" : "&#9654;";
  if (playing) {
    state.playTime = state.frame * data.control_dt;
    lastTick = null;
    requestAnimationFrame(tick);
  }
}

let lastTick = null;
function tick(now) {
  if (!state.playing) return;
  if (lastTick != null) {
    const ep = episode();
    state.playTime = (state.playTime + ((now - lastTick) / 1000) * state.speed) % (ep.frames * data.control_dt);
    const frame = Math.floor(state.playTime / data.control_dt);
    if (frame !== state.frame) showFrame(frame);
  }
  lastTick = now;
  requestAnimationFrame(tick);
}

data.episodes.forEach((ep, i) => {
  const option = document.createElement("option");
  option.value = String(i);
  option.textContent = ep.outcome === "reference" ? "clip" : `${i}: ${ep.outcome}${ep.failed_frame == null ? "" : " @" + ep.failed_frame}`;
  $("episode").append(option);
});
$("episode").disabled = data.episodes.length < 2;
$("episode").addEventListener("change", (e) => selectEpisode(parseInt(e.target.value, 10)));
$("play").addEventListener("click", () => setPlaying(!state.playing));
$("scrubber").addEventListener("input", (e) => {
  showFrame(parseInt(e.target.value, 10));
  state.playTime = state.frame * data.control_dt;
});
$("speed").addEventListener("change", (e) => { state.speed = parseFloat(e.target.value); });
$("ghost").disabled = !characters.reference;
$("goal-overlay").hidden = !goals;
$("ghost").addEventListener("change", (e) => {
  for (const group of characters.reference) group.visible = e.target.checked;
  render();
});
if (sourceFigure) {
  $("source").addEventListener("change", (e) => { sourceFigure.group.visible = e.target.checked; render(); });
  $("source-shift").addEventListener("input", (e) => { sourceFigure.shift = parseFloat(e.target.value) || 0; render(); });
}
$("follow").addEventListener("change", (e) => { state.follow = e.target.checked; showFrame(state.frame); });
window.addEventListener("keydown", (e) => {
  if (e.target instanceof HTMLInputElement && e.target.type !== "checkbox" && e.target.type !== "range") return;
  if (e.code === "Space") { e.preventDefault(); setPlaying(!state.playing); }
  if (e.code === "ArrowRight") showFrame(state.frame + 1);
  if (e.code === "ArrowLeft") showFrame(state.frame - 1);
});

// Orbit: drag rotates, shift-drag or right-drag pans, the wheel zooms.
canvas.addEventListener("contextmenu", (e) => e.preventDefault());
canvas.addEventListener("pointerdown", (e) => {
  canvas.setPointerCapture(e.pointerId);
  const pan = e.button === 2 || e.shiftKey;
  let last = [e.clientX, e.clientY];
  const move = (m) => {
    const [dx, dy] = [m.clientX - last[0], m.clientY - last[1]];
    last = [m.clientX, m.clientY];
    if (pan) {
      const scale = state.orbit.distance / canvas.clientHeight;
      const right = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 0);
      const up = new THREE.Vector3().setFromMatrixColumn(camera.matrix, 1);
      state.target.addScaledVector(right, -dx * scale).addScaledVector(up, dy * scale);
      state.follow = false;
      $("follow").checked = false;
    } else {
      state.orbit.azimuth -= dx * 0.008;
      state.orbit.elevation = Math.min(Math.max(state.orbit.elevation + dy * 0.008, -0.2), 1.45);
    }
    render();
  };
  const up = () => {
    canvas.removeEventListener("pointermove", move);
    canvas.removeEventListener("pointerup", up);
  };
  canvas.addEventListener("pointermove", move);
  canvas.addEventListener("pointerup", up);
});
canvas.addEventListener("wheel", (e) => {
  e.preventDefault();
  state.orbit.distance = Math.min(Math.max(state.orbit.distance * Math.exp(e.deltaY * 0.001), 0.5), 40);
  render();
}, { passive: false });

function resize() {
  const { clientWidth: w, clientHeight: h } = $("view");
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
  drawPlot();
  render();
}
new ResizeObserver(resize).observe($("view"));

// --- the error plot --------------------------------------------------------------------------
const SERIES = [
  { key: "pose", label: "pose error (root-relative)", color: "#d9732f" },
  { key: "ee_position", label: "end-effector error", color: "#7b4fc4" },
  { key: "global_mpjpe", label: "global MPJPE", color: "#8a94a0" },
];

function drawPlot() {
  const plot = $("plot");
  if (!errors) return;
  const ratio = window.devicePixelRatio || 1;
  const [w, h] = [plot.clientWidth, plot.clientHeight];
  plot.width = Math.round(w * ratio);
  plot.height = Math.round(h * ratio);
  const g = plot.getContext("2d");
  g.setTransform(ratio, 0, 0, ratio, 0, 0);
  g.clearRect(0, 0, w, h);
  const ep = episode();
  const [left, right, top, bottom] = [46, 10, 18, 22];
  let max = 0.05;
  for (const s of SERIES) for (let f = 0; f < ep.frames; f++) max = Math.max(max, errors[s.key][ep.first_row + f]);
  const x = (f) => left + (f / Math.max(ep.frames - 1, 1)) * (w - left - right);
  const y = (v) => top + (1 - v / max) * (h - top - bottom);
  g.font = "11px system-ui, sans-serif";
  g.strokeStyle = "#dde2e8";
  g.fillStyle = "#5a6573";
  g.lineWidth = 1;
  for (let i = 0; i <= 4; i++) {
    const v = (max * i) / 4;
    g.beginPath(); g.moveTo(left, y(v)); g.lineTo(w - right, y(v)); g.stroke();
    g.fillText(`${v.toFixed(2)} m`, 2, y(v) + 4);
  }
  g.fillText("0 s", left, h - 6);
  const end = `${((ep.frames - 1) * data.control_dt).toFixed(2)} s`;
  g.fillText(end, w - right - g.measureText(end).width, h - 6);
  let legendX = left + 40;
  for (const s of SERIES) {
    g.strokeStyle = s.color;
    g.lineWidth = s.key === "global_mpjpe" ? 1 : 2;
    g.beginPath();
    for (let f = 0; f < ep.frames; f++) {
      const v = errors[s.key][ep.first_row + f];
      if (f === 0) g.moveTo(x(f), y(v)); else g.lineTo(x(f), y(v));
    }
    g.stroke();
    g.fillStyle = s.color;
    g.fillRect(legendX, 5, 10, 3);
    g.fillStyle = "#3a4553";
    g.fillText(s.label, legendX + 14, 11);
    legendX += g.measureText(s.label).width + 36;
  }
  if (ep.failed_frame != null) {
    g.strokeStyle = "#d0302f";
    g.setLineDash([4, 3]);
    g.beginPath(); g.moveTo(x(ep.failed_frame), top); g.lineTo(x(ep.failed_frame), h - bottom); g.stroke();
    g.setLineDash([]);
    g.fillStyle = "#d0302f";
    g.fillText("failed", x(ep.failed_frame) + 3, h - bottom - 4);
  }
  g.strokeStyle = "#1d2530";
  g.lineWidth = 1.5;
  g.beginPath(); g.moveTo(x(state.frame), top); g.lineTo(x(state.frame), h - bottom); g.stroke();
  const row = ep.first_row + state.frame;
  $("plot-readout").textContent = `frame ${state.frame}: pose ${errors.pose[row].toFixed(3)} m, ` +
    `end effectors ${errors.ee_position[row].toFixed(3)} m and ${errors.ee_orientation[row].toFixed(3)} rad, ` +
    `global MPJPE ${errors.global_mpjpe[row].toFixed(3)} m`;
}

function seekFromPlot(e) {
  const plot = $("plot");
  const ep = episode();
  const fraction = (e.clientX - plot.getBoundingClientRect().left - 46) / Math.max(plot.clientWidth - 56, 1);
  showFrame(Math.round(Math.min(Math.max(fraction, 0), 1) * (ep.frames - 1)));
  state.playTime = state.frame * data.control_dt;
}
if (errors) {
  $("plot").addEventListener("pointerdown", (e) => {
    seekFromPlot(e);
    const move = (m) => seekFromPlot(m);
    $("plot").addEventListener("pointermove", move);
    window.addEventListener("pointerup", () => $("plot").removeEventListener("pointermove", move), { once: true });
  });
} else if (goals) {
  $("plot").hidden = true;
} else {
  $("plot").hidden = true;
  $("plot-readout").textContent = "No tracking errors to plot: this page shows a reference clip alone. " +
    "A replay of a trained policy plots its pose and end-effector errors here, frame by frame.";
}

// --- start -----------------------------------------------------------------------------------
const swatch = (track, label) => `<span class="swatch" style="background:#${COLORS[track].toString(16)}${track === solidTrack ? "" : "66"}"></span>${label}`;
$("legend").innerHTML = (goals
  ? swatch("simulated", "simulated") + swatch("goal", "goal")
  : tracks.simulated
    ? swatch("simulated", "simulated") + swatch("reference", "reference (ghost)")
    : swatch("reference", "reference")) + (sourceFigure ? swatch("source", "source skeleton") : "");
$("summary").textContent = `${data.motion_source} · ${data.producer}` + (data.checkpoint ? ` · ${data.checkpoint}` : "");
$("status").textContent = "";
resize();
selectEpisode(state.episode);
if (params.has("frame")) showFrame(parseInt(params.get("frame"), 10) || 0);
setPlaying(state.playing);
window.viewerReadyMs = performance.now();

// --- self-test (#selftest): what tests/viewer_page.rs asserts, written into the page ---------
function selfTest() {
  const gl = renderer.getContext();
  const pixels = () => {
    render();
    const [w, h] = [gl.drawingBufferWidth, gl.drawingBufferHeight];
    const out = new Uint8Array(w * h * 4);
    gl.readPixels(0, 0, w, h, gl.RGBA, gl.UNSIGNED_BYTE, out);
    return out;
  };
  const differing = (a, b) => {
    let n = 0;
    for (let i = 0; i < a.length; i += 4) {
      if (Math.abs(a[i] - b[i]) + Math.abs(a[i + 1] - b[i + 1]) + Math.abs(a[i + 2] - b[i + 2]) > 30) n++;
    }
    return n;
  };
  const solid = characters[solidTrack];
  showFrame(0);
  const first = pixels();
  const shown = scene.children.map((c) => c.visible);
  scene.children.forEach((c) => { c.visible = false; });
  const empty = pixels();
  scene.children.forEach((c, i) => { c.visible = shown[i]; });
  solid.forEach((g) => { g.visible = false; });
  const withoutCharacter = pixels();
  solid.forEach((g) => { g.visible = true; });
  const inView = solid.every((g) => {
    const p = g.getWorldPosition(new THREE.Vector3()).project(camera);
    return Math.abs(p.x) <= 1 && Math.abs(p.y) <= 1 && p.z > -1 && p.z < 1;
  });
  // The goal marker's own pixels, and where it and the overlay stand at frame 0.
  let goalPixels = null;
  let goalAtStart = null;
  let overlayAtStart = null;
  if (goalMarker) {
    goalMarker.visible = false;
    goalPixels = differing(first, pixels());
    goalMarker.visible = true;
    goalAtStart = goalMarker.position.clone();
    overlayAtStart = $("goal-overlay").textContent;
  }
  const before = solid.map((g) => g.position.clone());
  const middle = Math.floor((episode().frames - 1) / 2);
  const scrubber = $("scrubber");
  scrubber.value = String(middle);
  scrubber.dispatchEvent(new Event("input", { bubbles: true }));
  const moved = Math.max(...solid.map((g, b) => g.position.distanceTo(before[b])));
  const scrubbed = pixels();
  let goal = null;
  if (goalMarker) {
    // The last frame: every goal of the episode reached by then.
    showFrame(episode().frames - 1);
    goal = {
      marker_pixels: goalPixels,
      overlay_at_start: overlayAtStart,
      overlay_at_end: $("goal-overlay").textContent,
      reached_at_end: goals.reached[episode().first_row + episode().frames - 1],
      marker_moved_m: goalMarker.position.distanceTo(goalAtStart),
      marker_in_view_at_start: (() => {
        showFrame(0);
        const p = goalMarker.getWorldPosition(new THREE.Vector3()).project(camera);
        return Math.abs(p.x) <= 1 && Math.abs(p.y) <= 1;
      })(),
      ghost_drawn: !!characters.reference,
    };
    showFrame(middle);
  }
  // The source skeleton's own pixels at frame 0, its joints in view, and the checkbox hiding it.
  let source = null;
  if (sourceFigure) {
    showFrame(0);
    const withSource = pixels();
    sourceFigure.group.visible = false;
    const without = pixels();
    sourceFigure.group.visible = true;
    const checkbox = $("source");
    checkbox.checked = false;
    checkbox.dispatchEvent(new Event("change", { bubbles: true }));
    const hiddenByCheckbox = !sourceFigure.group.visible;
    checkbox.checked = true;
    checkbox.dispatchEvent(new Event("change", { bubbles: true }));
    source = {
      joints: sourceSkeleton.names.length,
      pixels: differing(withSource, without),
      joints_in_view: sourceFigure.joints.every((m) => {
        const p = m.getWorldPosition(new THREE.Vector3()).project(camera);
        return Math.abs(p.x) <= 1 && Math.abs(p.y) <= 1;
      }),
      checkbox_hides: hiddenByCheckbox,
      shown_again: sourceFigure.group.visible,
    };
    showFrame(middle);
  }
  const resources = performance.getEntriesByType("resource").map((r) => r.name)
    .filter((name) => !name.startsWith("blob:") && !name.startsWith("data:"));
  const result = {
    ready_ms: window.viewerReadyMs,
    canvas: [gl.drawingBufferWidth, gl.drawingBufferHeight],
    non_background_pixels: differing(first, empty),
    character_pixels: differing(first, withoutCharacter),
    bodies_in_view: inView,
    scrubbed_to: state.frame,
    scrubber_frame: middle,
    body_moved_m: moved,
    scrub_changed_pixels: differing(first, scrubbed),
    episodes: data.episodes.length,
    has_plot: !!errors,
    goal,
    source,
    resources,
    errors: window.viewerErrors,
  };
  const out = $("selftest-result");
  out.textContent = JSON.stringify(result);
  out.dataset.done = "1";
}
if (params.has("selftest")) {
  try {
    selfTest();
  } catch (e) {
    window.viewerErrors.push("self-test: " + e);
    $("selftest-result").textContent = JSON.stringify({ errors: window.viewerErrors });
  }
}
