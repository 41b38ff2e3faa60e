// pyclpt's viewer page: shows the pictures the server streams over a WebSocket and sends camera moves and
// settings back (pyclpt/viewer/server.py has the protocol).
"use strict";
const $ = (id) => document.getElementById(id);
const img = $("frame");
let ws = null;
let imageUrl = null;
let editing = null;  // the control being edited: its value is not overwritten by the server's status

function send(msg) {
  if (!["camera", "ping", "viewport"].includes(msg.type)) $("notice").textContent = "";  // a new request
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(msg));
}

// the device setting's choices, as the server lists them when the page connects
function showDevices(devices) {
  const select = $("device");
  const current = select.value;
  select.textContent = "";
  for (const d of devices) {
    const option = document.createElement("option");
    option.value = d.id;
    option.textContent = d.id + " " + d.name;
    select.append(option);
  }
  if (current) select.value = current;
}

// the picture area's size: the server renders a frame that fills it (up to its maximum size)
function sendViewport() {
  const stage = $("stage");
  send({type: "viewport", width: Math.max(1, stage.clientWidth), height: Math.max(1, stage.clientHeight),
        scale: window.devicePixelRatio || 1});
}
let resizeTimer = null;
new ResizeObserver(() => {
  clearTimeout(resizeTimer);
  resizeTimer = setTimeout(sendViewport, 150);  // once the window has stopped changing
}).observe($("stage"));

function showStatus(s) {
  $("title").textContent = "pyclpt · " + s.scene;
  $("fps").textContent = s.fps.toFixed(1) + " fps · " + s.pictures_fps.toFixed(0) + " shown";
  $("spp").textContent = s.spp;
  $("frames").textContent = s.frame;
  $("frame_ms").textContent = s.frame_ms === null ? "–" : s.frame_ms.toFixed(1) + " ms";
  $("size").textContent = s.width + " × " + s.height + (s.max_size ? " (follows the window, ≤ " + s.max_size + ")" : "");
  $("reprojections").textContent = s.reprojections;
  $("state").textContent = s.error ? "failed" : s.rendering ? "rendering" : "paused";
  $("device-name").textContent = s.device;
  $("error").textContent = s.error || "";
  for (const [name, value] of Object.entries(s.settings)) {
    const el = $(name);
    if (el && el !== editing) el.value = value;
  }
  $("keyframes").textContent = s.keyframes + (s.keyframes === 1 ? " keyframe" : " keyframes") +
    (s.playing ? " · playing" : "");
  showKernels(s.kernels || []);
  img.dataset.shown = s.shown;
  img.dataset.frame = s.frame;
}

// per-kernel device time per frame: one bar each, scaled to the longest
function showKernels(rows) {
  const box = $("kernels");
  box.textContent = "";
  const longest = Math.max(1e-9, ...rows.map((r) => r.ms));
  for (const r of rows) {
    const row = document.createElement("div");
    row.className = "kernel";
    const bar = document.createElement("div");
    bar.className = "bar";
    bar.style.width = (100 * r.ms / longest).toFixed(1) + "%";
    const label = document.createElement("span");
    label.textContent = r.kernel + " " + r.ms.toFixed(2) + " ms";
    row.append(bar, label);
    box.append(row);
  }
}

function connect() {
  const url = (location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws";
  ws = new WebSocket(url);
  ws.binaryType = "blob";
  ws.onopen = () => { $("state").textContent = "connected"; sendViewport(); };
  ws.onmessage = (ev) => {
    if (typeof ev.data !== "string") {
      const next = URL.createObjectURL(ev.data);
      img.onload = () => { if (imageUrl) URL.revokeObjectURL(imageUrl); imageUrl = next; };
      img.src = next;
      return;
    }
    const msg = JSON.parse(ev.data);
    if (msg.type === "status") showStatus(msg);
    else if (msg.type === "devices") showDevices(msg.devices);
    else if (msg.type === "saved") $("saved").textContent = "wrote " + msg.paths.join(", ");
    else if (msg.type === "lookat") {
      $("lookat").style.display = "block";
      $("lookat").value = msg.xml;
      $("saved").textContent = "wrote " + msg.path;
    } else if (msg.type === "keyframes") {
      $("keyframes").textContent = msg.count + (msg.count === 1 ? " keyframe" : " keyframes");
      if (msg.path) $("saved").textContent = "wrote " + msg.path;
    } else if (msg.type === "error") $("notice").textContent = msg.message;  // kept until the next request
  };
  ws.onclose = () => {
    $("state").textContent = "disconnected: retrying";
    setTimeout(connect, 1000);
  };
}

// -- settings --------------------------------------------------------------------------------------
for (const el of document.querySelectorAll("[data-setting]")) {
  el.addEventListener("focus", () => { editing = el; });
  el.addEventListener("blur", () => { if (editing === el) editing = null; });
  el.addEventListener("change", () => {
    const numeric = el.type === "number" || el.type === "range";
    send({type: "set", name: el.dataset.setting, value: numeric ? Number(el.value) : el.value});
  });
}
$("exposure").addEventListener("input", (e) => send({type: "set", name: "exposure", value: Number(e.target.value)}));
$("save").onclick = () => send({type: "save"});
$("lookat-button").onclick = () => send({type: "lookat"});
$("reset").onclick = () => send({type: "camera", op: "reset"});
for (const op of ["add", "play", "save", "clear"]) {
  $("key-" + op).onclick = () => send({type: "keyframe", op: op, spacing: Number($("key-spacing").value)});
}

// -- camera: moves gathered per animation frame, sent as one message each ---------------------------
const pending = {yaw: 0, pitch: 0, dx: 0, dy: 0, zoom: 1};
const keys = new Set();
let drag = null;
const DEGREES_PER_PIXEL = 0.3;
const FLY_SPEED = 0.25;  // scene sizes per second

img.addEventListener("contextmenu", (e) => e.preventDefault());
img.addEventListener("pointerdown", (e) => {
  img.focus();
  img.setPointerCapture(e.pointerId);
  drag = {x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey};
});
img.addEventListener("pointermove", (e) => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag.x = e.clientX; drag.y = e.clientY;
  if (drag.pan) {
    const w = img.getBoundingClientRect().width || 1;
    pending.dx += dx / w; pending.dy += dy / w;
  } else {
    pending.yaw -= dx * DEGREES_PER_PIXEL; pending.pitch += dy * DEGREES_PER_PIXEL;
  }
});
img.addEventListener("pointerup", () => { drag = null; });
img.addEventListener("wheel", (e) => { e.preventDefault(); pending.zoom *= Math.exp(e.deltaY * 0.001); },
                     {passive: false});
img.addEventListener("keydown", (e) => { if ("wasdqe".includes(e.key.toLowerCase())) keys.add(e.key.toLowerCase()); });
img.addEventListener("keyup", (e) => keys.delete(e.key.toLowerCase()));
img.addEventListener("blur", () => keys.clear());

let last = performance.now();
function tick(now) {
  const dt = Math.min((now - last) / 1000, 0.1);
  last = now;
  if (pending.yaw || pending.pitch) send({type: "camera", op: "orbit", yaw: pending.yaw, pitch: pending.pitch});
  if (pending.dx || pending.dy) send({type: "camera", op: "pan", dx: pending.dx, dy: pending.dy});
  if (pending.zoom !== 1) send({type: "camera", op: "zoom", factor: pending.zoom});
  pending.yaw = pending.pitch = pending.dx = pending.dy = 0; pending.zoom = 1;
  if (keys.size) {
    const k = (a, b) => (keys.has(a) ? 1 : 0) - (keys.has(b) ? 1 : 0);
    const step = FLY_SPEED * dt;
    send({type: "camera", op: "fly", forward: k("w", "s") * step, right: k("d", "a") * step, up: k("e", "q") * step});
  }
  requestAnimationFrame(tick);
}
requestAnimationFrame(tick);
// keep the session rendering while the page is open, even when nothing new arrives
setInterval(() => send({type: "ping"}), 1000);
connect();
