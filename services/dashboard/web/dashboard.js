// BuddyBot dashboard page: draws what the server streams over /ws (docs/dashboard.md).
// Text frames are JSON {t: slot, v: value}; binary frames are camera images
// (4-byte big-endian header length, JSON header, JPEG). Everything is drawn
// here (canvas), so the server never renders anything but the JPEG.
"use strict";

const $ = (id) => document.getElementById(id);
const D = {
  hello: null, enums: {}, offsetMs: 0, span: 30,
  sensors: {},          // "device/radar" -> {points: [[t, moving_cm, still_cm]], last: view}
  faces: null, image: null, imageHeader: null, decoding: false, pendingImage: null,
  presence: null, rules: null, controller: null,
  counts: { messages: 0, images: 0, frames: 0 },
  presenceSeenAt: {},   // presence text -> Date.now() when first shown (tests measure latency)
  nextId: 1,
  quiet: new Set(),     // ids of requests whose reply the header does not show
  known: null,          // the enrolled people (identity/list), as the server last listed them
};
window.dash = D;

const nowS = () => (Date.now() + D.offsetMs) / 1000;
const name = (kind, n) => (D.enums[kind] && D.enums[kind][n]) || String(n);
const fmt = (x, digits = 2) => (x === null || x === undefined ? "–" : Number(x).toFixed(digits));
function ago(ns) {
  if (!ns) return "never";
  const s = nowS() - ns / 1e9;
  return s < 90 ? `${s.toFixed(0)} s ago` : `${(s / 60).toFixed(1)} min ago`;
}
// Fast-changing text (gaze and pupil at the camera's rate, faces, radar values)
// is written at most 4 times a second, and only when it changed: each write
// makes the browser lay out and paint again, which cost a headless Chromium
// ~35 % of a core at 100 messages/s. State changes (presence, controller,
// nodes) are written at once.
const pendingText = new Map();
function later(el, text) { pendingText.set(el, text); }
function put(el, text) { if (el.textContent !== text) el.textContent = text; }
setInterval(() => {
  for (const [el, text] of pendingText) if (el.textContent !== text) el.textContent = text;
  pendingText.clear();
}, 250);
function badge(el, text, cls) {
  put(el, text);
  const name = "badge " + (cls || "");
  if (el.className !== name) el.className = name;
}

// --- connection ----------------------------------------------------------------------
let ws = null;
function connect() {
  ws = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + "/ws");
  ws.binaryType = "arraybuffer";
  ws.onmessage = (ev) => {
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      D.counts.messages++;
      const handler = handlers[msg.t];
      if (handler) handler(msg.v);
    } else {
      onImage(ev.data);
    }
  };
  ws.onclose = () => { badge($("conn"), "dashboard server unreachable", "bad"); setTimeout(connect, 1000); };
}
function send(cmd) {
  cmd.id = D.nextId++;
  if (ws && ws.readyState === WebSocket.OPEN) ws.send(JSON.stringify(cmd));
  else showReply({ ok: false, text: "not connected" });
  return cmd.id;
}
function showReply(r) { const el = $("reply"); el.textContent = r.text; el.className = "reply" + (r.ok ? "" : " bad"); D.lastReply = r; }

const handlers = {
  hello(v) {
    setTimeout(() => D.quiet.add(send({ op: "known" })), 0);  // the panel shows the answer
    D.hello = v; D.enums = v.enums; D.span = v.history_s;
    D.viewer = v.role === "viewer";  // the server refuses a viewer's presses anyway
    $("control").disabled = D.viewer;
    $("control-row").title = D.viewer ? VIEWER_ONLY : "";
    D.offsetMs = v.now * 1000 - Date.now();
    $("camera-name").textContent = v.camera;
    if ($("eye-frame").src !== v.eye_url) $("eye-frame").src = v.eye_url;
    const box = $("expr-buttons"); box.textContent = "";
    for (const e of v.expressions) {
      const b = document.createElement("button");
      b.textContent = e.replace(/^(EYE_|ANIMATE_)/, "").toLowerCase();
      b.dataset.title = "set the expression " + e; b.dataset.expression = e;
      b.onclick = () => send({ op: "expression", action: e });
      box.appendChild(b);
    }
    showControl();
  },
  status(v) { badge($("conn"), v.bus ? "on the bus" : "connecting to the robot…", v.bus ? "ok" : "warn"); },
  history(v) {
    D.offsetMs = v.now * 1000 - Date.now();
    for (const [key, points] of Object.entries(v.sensors)) sensor(key).points = points.slice();
    drawAllRadar();
  },
  radar(frames) {
    for (const f of frames) {
      const s = sensor(f.sensor);
      const last = s.points.length ? s.points[s.points.length - 1][0] : -Infinity;
      if (f.t > last) s.points.push([f.t, f.moving_cm, f.still_cm]);
      s.last = f; D.counts.frames++;
    }
    for (const key of new Set(frames.map((f) => f.sensor))) updateSensorText(key);
    drawAllRadar();
  },
  presence(v) {
    D.presence = v;
    const text = v ? `${name("PresenceState", v.presence_state)} ${fmt(v.distance_m)} m` : "unknown";
    badge($("presence"), text, v && v.presence_state === 1 ? "ok" : "");
    if (!(text in D.presenceSeenAt)) D.presenceSeenAt[text] = Date.now();
    if (v) {
      $("p-state").textContent = name("PresenceState", v.presence_state);
      $("p-target").textContent = name("PresenceTarget", v.target_state).toLowerCase();
      $("p-distance").textContent = `${fmt(v.distance_m)} m`;
    }
    showPresenceAge();
    drawAllRadar();
  },
  rules(v) {
    D.rules = v;
    $("rules").textContent = v ? `range ${fmt(v.range_m)} m (leave at ${fmt(v.range_m + (v.exit_margin_m || 0))} m), `
      + `absence hold ${fmt(v.absence_hold_s, 1)} s, target hold ${fmt(v.target_hold_s, 1)} s`
      : "unknown (radar-presence does not answer)";
    drawAllRadar();
  },
  faces(v) { D.faces = v; scheduleCamera(); describeFaces(); },
  controller(v) { D.controller = v; showController(); },
  expression(v) { put($("expression"), name("ExpressionAction", v.action)); },
  direction(v) {
    later($("gaze"), `${fmt(v.msg.yaw, 1)}° / ${fmt(v.msg.pitch, 1)}°`);
    const l = v.latency;
    later($("latency"), l.n ? `${fmt(l.last_ms, 0)} ms (p50 ${fmt(l.p50_ms, 0)}, p95 ${fmt(l.p95_ms, 0)})` : "–");
  },
  pupil(v) { later($("pupil"), `${fmt(v.dilation_percentage, 0)} %`); },
  lids(v) {
    later($("lids"), `${name("EyeId", v.eye_id).toLowerCase()}: top ${fmt(v.top_lid_position, 0)} %, bottom ${fmt(v.bottom_lid_position, 0)} %`);
  },
  nodes(rows) { D.nodes = rows; showNodes(); },
  sounds(names) {
    const box = $("sound-buttons"); box.textContent = "";
    for (const s of names) {
      const b = document.createElement("button");
      b.textContent = "▶ " + s; b.dataset.title = "play " + s; b.dataset.sound = s;
      b.onclick = () => send({ op: "play", sound: s });
      box.appendChild(b);
    }
    const stop = document.createElement("button");
    stop.textContent = "■ stop"; stop.className = "stop"; stop.dataset.title = "stop the sound playing";
    stop.onclick = () => send({ op: "stop" });
    box.appendChild(stop);
    showControl();
  },
  leases(v) { D.leases = v; showControl(); showLeases(); },
  map(v) { D.map = v; showRadarView(); scheduleMap(); },
  reply(r) { if (!D.quiet.delete(r.id)) showReply(r); },
  known(v) { D.known = v; showKnown(); },
  present(v) { showPresent(v); },
};

// --- camera ----------------------------------------------------------------------------
function onImage(buf) {
  const size = new DataView(buf).getUint32(0);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buf, 4, size)));
  const blob = new Blob([new Uint8Array(buf, 4 + size)], { type: "image/jpeg" });
  D.counts.images++;
  if (D.decoding) { D.pendingImage = [header, blob]; return; }  // only the newest waits
  decode(header, blob);
}
function decode(header, blob) {
  D.decoding = true;
  createImageBitmap(blob).then((bmp) => {
    if (D.image && D.image.close) D.image.close();
    D.image = bmp; D.imageHeader = header;
    later($("camera-info"), `${header.width}×${header.height}`);
    scheduleCamera();
  }).catch(() => {}).finally(() => {
    D.decoding = false;
    if (D.pendingImage) { const [h, b] = D.pendingImage; D.pendingImage = null; decode(h, b); }
  });
}
// Faces come at the camera's rate and images at max_image_fps: draw once per
// display frame at most, whatever arrived (the browser's CPU is the cost).
let cameraQueued = false;
function scheduleCamera() {
  if (cameraQueued) return;
  cameraQueued = true;
  requestAnimationFrame(() => { cameraQueued = false; drawCamera(); });
}
function drawCamera() {
  const c = $("camera"), g = c.getContext("2d");
  const w = D.imageHeader ? D.imageHeader.width : (D.faces ? D.faces.width : c.width);
  const h = D.imageHeader ? D.imageHeader.height : (D.faces ? D.faces.height : c.height);
  if (c.width !== w || c.height !== h) { c.width = w; c.height = h; }
  g.fillStyle = "#000"; g.fillRect(0, 0, w, h);
  if (D.image) g.drawImage(D.image, 0, 0, w, h);
  else { g.fillStyle = "#8b93a0"; g.font = `${Math.round(h / 20)}px sans-serif`; g.fillText("no camera image", w * 0.05, h * 0.1); }
  const f = D.faces;
  if (!f) return;
  const sx = w / f.width, sy = h / f.height, lw = Math.max(2, Math.round(w / 200));
  g.font = `bold ${Math.max(12, Math.round(h / 26))}px sans-serif`;
  for (const face of f.faces) {
    const color = face.followed ? "#3fb950" : "#d29922";
    g.strokeStyle = color; g.lineWidth = lw;
    g.strokeRect(face.x0 * sx, face.y0 * sy, (face.x1 - face.x0) * sx, (face.y1 - face.y0) * sy);
    g.fillStyle = "#ff4fd8";
    for (const k of face.keypoints) { g.beginPath(); g.arc(k.x * sx, k.y * sy, lw * 1.5, 0, 2 * Math.PI); g.fill(); }
    let label = `${fmt(face.score)}`;
    if (face.followed && f.distance_m !== null) label += ` · ${fmt(f.distance_m)} m`;
    const tw = g.measureText(label).width, th = Math.max(12, Math.round(h / 26));
    const ty = Math.max(th + 4, face.y0 * sy - lw - 5);
    g.fillStyle = "rgba(0, 0, 0, 0.6)"; g.fillRect(face.x0 * sx - 2, ty - th, tw + 6, th + 3);
    g.fillStyle = color;
    g.fillText(label, face.x0 * sx + 1, ty);
  }
}
function describeFaces() {
  const f = D.faces, el = $("faces");
  if (!f) return;
  if (!f.faces.length) { later(el, "no face in the last frame"); return; }
  const followed = f.faces.find((x) => x.followed);
  const parts = [`${f.faces.length} face${f.faces.length > 1 ? "s" : ""}`,
    f.tracked ? "tracked in its crop" : "whole-frame detection"];
  if (followed) parts.push(`followed: score ${fmt(followed.score)}, distance ${fmt(f.distance_m)} m`);
  const cues = f.cues.map((c) => `${c.name} ${c.distance_m === null ? "–" : fmt(c.distance_m)} m `
    + `(${c.status === "used" ? "weight " + fmt(c.weight) : c.status})`);
  later(el, parts.join(" · ") + (cues.length ? " — cues: " + cues.join(", ") : ""));
}

// --- radar -----------------------------------------------------------------------------
function sensor(key) {
  if (!D.sensors[key]) {
    const div = document.createElement("div");
    div.className = "sensor"; div.dataset.sensor = key;
    div.innerHTML = `<div class="line"><b>sensor ${key}</b><span class="state"></span>`
      + `<span class="legend-moving">moving <span class="mv"></span></span>`
      + `<span class="legend-still">still <span class="st"></span></span></div>`
      + `<canvas class="plot" width="760" height="380"></canvas>`
      + `<canvas class="bars" width="760" height="240"></canvas>`;
    const box = $("sensors");
    if (!Object.keys(D.sensors).length) box.textContent = "";
    box.appendChild(div);
    D.sensors[key] = { points: [], last: null, el: div };
  }
  return D.sensors[key];
}
function updateSensorText(key) {
  const s = D.sensors[key], f = s.last;
  if (!f) return;
  later(s.el.querySelector(".state"), f.state.toLowerCase().replace(/_/g, " "));
  later(s.el.querySelector(".mv"), `${fmt(f.moving_cm / 100)} m, energy ${f.moving_energy}`);
  later(s.el.querySelector(".st"), `${fmt(f.still_cm / 100)} m, energy ${f.still_energy}`);
}
let radarQueued = false;
function drawAllRadar() {
  if (radarQueued) return;
  radarQueued = true;
  requestAnimationFrame(() => {
    radarQueued = false;
    for (const key of Object.keys(D.sensors)) { drawPlot(D.sensors[key]); drawBars(D.sensors[key]); }
  });
  showRadarView();
}
setInterval(drawAllRadar, 200);  // the time axis moves on between frames
setInterval(() => { showController(); showPresenceAge(); }, 500);
function showPresenceAge() {
  if (D.presence) put($("p-since"), ago(D.presence.stamp_ns));
}

// --- the angle radars' top-down map --------------------------------------------------
// The server sends the scene in canvas pixels (services/dashboard/radar_map.py and
// map_geometry.py decide what goes where); the page only paints it. Shown in place
// of the distance plots once an angle radar reports; with LD2410 sensors as well,
// two tabs switch between them.
const MAP_COLOURS = ["#ffa657", "#79c0ff", "#d2a8ff", "#f778ba", "#56d4dd", "#e3b341"];
const FOLLOWED = "#3fb950";
const TRUTH = "#f0f3f6";
const RADAR_TITLES = {
  distance: 'Radar <span class="dim">distance over time and gate energies per sensor</span>',
  map: 'Radar map <span class="dim">from above, forward up</span>',
};
for (const b of document.querySelectorAll("#radar-tabs button")) {
  b.onclick = () => { D.radarView = b.dataset.view; showRadarView(); scheduleMap(); drawAllRadar(); };
}
function showRadarView() {
  const both = !!D.map && Object.keys(D.sensors).length > 0;
  const view = D.map ? (both && D.radarView) || "map" : "distance";
  const tabs = $("radar-tabs");
  if (tabs.hidden === both) tabs.hidden = !both;
  for (const b of tabs.querySelectorAll("button")) b.classList.toggle("on", b.dataset.view === view);
  if ($("map-box").hidden !== (view !== "map")) {
    $("map-box").hidden = view !== "map";
    $("sensors").hidden = view === "map";
    $("radar-title").innerHTML = RADAR_TITLES[view];
  }
}
let mapQueued = false;
function scheduleMap() {
  if (mapQueued) return;
  mapQueued = true;
  requestAnimationFrame(() => { mapQueued = false; drawMap(); });
}
function poly(g, pts) {
  g.beginPath(); g.moveTo(pts[0][0], pts[0][1]);
  for (const p of pts.slice(1)) g.lineTo(p[0], p[1]);
  g.closePath();
}
function drawMap() {
  const v = D.map, c = $("map");
  if (!v || $("map-box").hidden) return;
  if (c.width !== v.size[0] || c.height !== v.size[1]) { c.width = v.size[0]; c.height = v.size[1]; }
  const g = c.getContext("2d"), [W, H] = v.size, [ou, ov] = v.origin, now = nowS();
  g.clearRect(0, 0, W, H);
  g.font = "22px sans-serif"; g.lineWidth = 1.5;
  // Distance rings, labelled straight ahead.
  g.strokeStyle = "#2c323c"; g.fillStyle = "#8b93a0";
  for (const r of v.rings) {
    g.beginPath(); g.arc(ou, ov, r.px, 0, 2 * Math.PI); g.stroke();
    g.fillText(`${r.m} m`, ou + 6, ov - r.px + 20);
  }
  g.beginPath(); g.moveTo(ou, 0); g.lineTo(ou, H); g.moveTo(0, ov); g.lineTo(W, ov); g.stroke();
  // The camera's field of view.
  if (v.fov) {
    g.fillStyle = "rgba(88, 166, 255, 0.09)"; poly(g, v.fov.poly); g.fill();
    g.strokeStyle = "rgba(88, 166, 255, 0.55)"; g.setLineDash([10, 8]); g.lineWidth = 2;
    const p = v.fov.poly, a = p[1], b = p[p.length - 1];
    g.beginPath(); g.moveTo(ou, ov); g.lineTo(a[0], a[1]); g.moveTo(ou, ov); g.lineTo(b[0], b[1]); g.stroke();
    g.setLineDash([]);
  }
  // Presence zones: detect green, ignore red and hatched.
  for (const z of v.zones) {
    const ignore = z.mode === "ignore", colour = ignore ? "#f85149" : "#3fb950";
    g.fillStyle = ignore ? "rgba(248, 81, 73, 0.16)" : "rgba(63, 185, 80, 0.10)";
    poly(g, z.poly); g.fill();
    if (ignore) {
      g.save(); poly(g, z.poly); g.clip();
      g.strokeStyle = "rgba(248, 81, 73, 0.35)"; g.lineWidth = 2; g.beginPath();
      for (let k = -H; k < W; k += 18) { g.moveTo(k, H); g.lineTo(k + H, 0); }
      g.stroke(); g.restore();
    }
    g.strokeStyle = colour; g.lineWidth = 2.5; poly(g, z.poly); g.stroke();
    const left = Math.min(...z.poly.map((p) => p[0])), top = Math.min(...z.poly.map((p) => p[1]));
    g.fillStyle = colour; g.fillText(z.name || z.mode, Math.max(4, left + 6), Math.max(20, top + 22));
  }
  // Trails (fading with age), then the targets now.
  g.lineCap = "round";
  for (const s of v.sensors) {
    const colour = MAP_COLOURS[s.index % MAP_COLOURS.length];
    g.strokeStyle = colour; g.lineWidth = 7;
    for (const t of s.trails) {
      for (let i = 1; i < t.length; i++) {
        g.globalAlpha = Math.max(0, Math.min(1, 1 - (now - t[i][2]) / v.trail_s)) * 0.8;
        g.beginPath(); g.moveTo(t[i - 1][0], t[i - 1][1]); g.lineTo(t[i][0], t[i][1]); g.stroke();
      }
    }
    g.globalAlpha = 1;
  }
  // People: the followed one ringed in green with a line from the robot.
  for (const p of v.people) {
    const colour = p.followed ? FOLLOWED : "#8b93a0";
    g.strokeStyle = colour; g.fillStyle = colour; g.lineWidth = p.followed ? 4 : 2;
    const label = `person ${p.id}${p.name ? " " + p.name : ""}`;
    if (p.at) {
      if (p.followed) {
        g.setLineDash([6, 6]); g.beginPath(); g.moveTo(ou, ov); g.lineTo(p.at[0], p.at[1]); g.stroke();
        g.setLineDash([]);
      }
      g.beginPath(); g.arc(p.at[0], p.at[1], 24, 0, 2 * Math.PI); g.stroke();
      g.fillText(label, p.at[0] - 40, p.at[1] - 32);
    } else if (p.followed) {  // no bearing: everywhere at that distance
      g.setLineDash([4, 10]); g.beginPath(); g.arc(ou, ov, p.ring_px, 0, 2 * Math.PI); g.stroke();
      g.setLineDash([]); g.fillText(`${label}, no bearing`, ou + 8, ov - p.ring_px - 8);
    }
  }
  for (const s of v.sensors) {
    const colour = MAP_COLOURS[s.index % MAP_COLOURS.length];
    for (const t of s.targets) {
      const [u, w] = t.at;
      g.fillStyle = colour; g.beginPath(); g.arc(u, w, 13, 0, 2 * Math.PI); g.fill();
      g.strokeStyle = "#101318"; g.lineWidth = 3; g.stroke();
      g.fillStyle = "#e3e6ea"; g.fillText(`${fmt(t.distance_m, 1)} m`, u + 30, w + 8);
    }
  }
  // The simulated world's truth (only while simulating): white diamonds where the
  // people really are, an arrow where they face; clutter as a small cross.
  if (v.truth) {
    g.lineWidth = 2.5; g.strokeStyle = TRUTH; g.fillStyle = TRUTH;
    for (const p of v.truth.people) {
      const [u, w] = p.at;
      g.setLineDash(p.in_camera ? [] : [5, 5]);
      g.beginPath(); g.moveTo(u, w - 16); g.lineTo(u + 16, w); g.lineTo(u, w + 16); g.lineTo(u - 16, w);
      g.closePath(); g.stroke(); g.setLineDash([]);
      g.beginPath(); g.moveTo(u, w); g.lineTo(p.facing[0], p.facing[1]); g.stroke();
      const seen = [p.in_radar ? "radar" : "", p.in_camera ? "camera" : ""].filter(Boolean);
      g.fillText(`truth ${p.id}${p.name ? " " + p.name : ""}${seen.length ? "" : " (unseen)"}`,
        u + 20, w + 28);
    }
    for (const c of v.truth.clutter) {
      const [u, w] = c.at;
      g.beginPath(); g.moveTo(u - 10, w - 10); g.lineTo(u + 10, w + 10);
      g.moveTo(u + 10, w - 10); g.lineTo(u - 10, w + 10); g.stroke();
      g.fillText(c.kind, u + 14, w + 8);
    }
  }
  // The robot: a wedge pointing forward (up).
  g.fillStyle = "#a371f7";
  g.beginPath(); g.moveTo(ou, ov - 22); g.lineTo(ou + 16, ov + 14); g.lineTo(ou - 16, ov + 14); g.closePath(); g.fill();
  // Legend: one line per sensor, bottom left.
  g.font = "24px sans-serif";
  v.sensors.forEach((s, i) => {
    g.fillStyle = MAP_COLOURS[s.index % MAP_COLOURS.length];
    g.fillText(`● radar ${s.key}${s.silent ? " (silent)" : ""}`, 12, H - 14 - 30 * (v.sensors.length - 1 - i));
  });
  if (v.truth) {
    g.fillStyle = TRUTH;
    g.fillText(`◇ simulated truth: ${v.truth.scenario} at ${fmt(v.truth.t_s, 0)} s`, 12,
      H - 14 - 30 * v.sensors.length);
  }
  const n = v.sensors.reduce((k, s) => k + s.targets.length, 0);
  const followed = v.people.find((p) => p.followed);
  const parts = [`${n} target${n === 1 ? "" : "s"}, trails ${fmt(v.trail_s, 0)} s`];
  if (followed) parts.push(`following person ${followed.id} at ${fmt(followed.distance_m, 1)} m`
    + (followed.yaw_deg === null ? "" : `, ${fmt(followed.yaw_deg, 0)}°`));
  parts.push(v.fov ? `camera view ${fmt(v.fov.hfov_deg, 0)}° (${v.fov.from})` : "camera view unknown");
  if (v.zones.length) parts.push(`zones from ${v.zones_from}`);
  later($("map-info"), parts.join(" · "));
}
window.dashMap = drawMap;  // tests draw at once instead of waiting for the next frame

const PLOT = { left: 44, right: 10, top: 12, bottom: 28 };
function drawPlot(s) {
  const c = s.el.querySelector(".plot"), g = c.getContext("2d"), W = c.width, H = c.height;
  const now = nowS(), span = D.span;
  const t0 = now - span;
  while (s.points.length && s.points[0][0] < t0 - 1) s.points.shift();
  const r = D.rules;
  let ymax = 6;
  if (r) ymax = Math.max(ymax, Math.ceil(r.range_m + (r.exit_margin_m || 0) + 0.5));
  for (const p of s.points) ymax = Math.max(ymax, Math.ceil(Math.max(p[1], p[2]) / 100));
  const pw = W - PLOT.left - PLOT.right, ph = H - PLOT.top - PLOT.bottom;
  const X = (t) => PLOT.left + ((t - t0) / span) * pw;
  const Y = (m) => PLOT.top + ph - (m / ymax) * ph;
  g.clearRect(0, 0, W, H);
  g.font = "22px sans-serif"; g.lineWidth = 1;
  g.strokeStyle = "#2c323c"; g.fillStyle = "#8b93a0";
  for (let m = 0; m <= ymax; m++) {
    g.beginPath(); g.moveTo(PLOT.left, Y(m)); g.lineTo(W - PLOT.right, Y(m)); g.stroke();
    g.fillText(`${m} m`, 2, Y(m) + 6);
  }
  for (let k = 0; k <= span; k += span > 60 ? 30 : 10) {
    g.fillText(k === 0 ? "now" : `-${k}s`, X(now - k) - (k === 0 ? 34 : 18), H - 6);
  }
  if (r) {
    g.strokeStyle = "#3fb950"; g.lineWidth = 2;
    g.beginPath(); g.moveTo(PLOT.left, Y(r.range_m)); g.lineTo(W - PLOT.right, Y(r.range_m)); g.stroke();
    g.fillStyle = "#3fb950"; g.fillText(`range ${fmt(r.range_m, 1)} m`, PLOT.left + 8, Y(r.range_m) - 6);
    g.setLineDash([8, 6]);
    if (r.exit_margin_m) {
      const ex = r.range_m + r.exit_margin_m;
      g.lineWidth = 1; g.beginPath(); g.moveTo(PLOT.left, Y(ex)); g.lineTo(W - PLOT.right, Y(ex)); g.stroke();
    }
    g.strokeStyle = "#a371f7"; g.fillStyle = "#a371f7"; g.lineWidth = 2;
    // The holds: how far back a reading still counts (drawn from "now" backwards).
    g.textAlign = "right";
    for (const [label, hold, row] of [["absence hold", r.absence_hold_s, 1], ["target hold", r.target_hold_s, 2]]) {
      if (!hold || hold > span) continue;
      g.beginPath(); g.moveTo(X(now - hold), PLOT.top); g.lineTo(X(now - hold), PLOT.top + ph); g.stroke();
      g.fillText(`${label} ${fmt(hold, 1)} s`, X(now - hold) - 6, PLOT.top + 24 * row);
    }
    g.textAlign = "left";
    g.setLineDash([]);
  }
  const line = (idx, color, width) => {
    g.strokeStyle = color; g.lineWidth = width; g.beginPath();
    let first = true;
    for (const p of s.points) {
      if (p[0] < t0) continue;
      const x = X(p[0]), y = Y(p[idx] / 100);
      if (first) { g.moveTo(x, y); first = false; } else g.lineTo(x, y);
    }
    g.stroke();
  };
  line(2, "#58a6ff", 5); line(1, "#f0883e", 2.5);  // still under moving: both show when equal
  const p = D.presence;
  if (p) {
    const inRange = p.presence_state === 1;
    g.fillStyle = inRange ? "#3fb950" : "#8b93a0";
    g.beginPath(); g.arc(W - PLOT.right - 8, Y(p.distance_m), 8, 0, 2 * Math.PI); g.fill();
  }
}
const BARS = { left: 44, right: 10, top: 10, bottom: 30 };
function barGeometry(W, H) {
  const pw = W - BARS.left - BARS.right, ph = H - BARS.top - BARS.bottom, slot = pw / 9;
  return { slot, ph, base: BARS.top + ph, x: (gate, which) => BARS.left + gate * slot + slot * (which ? 0.52 : 0.1), bw: slot * 0.38 };
}
function drawBars(s) {
  const c = s.el.querySelector(".bars"), g = c.getContext("2d"), W = c.width, H = c.height;
  g.clearRect(0, 0, W, H);
  const f = s.last;
  g.font = "20px sans-serif"; g.fillStyle = "#8b93a0";
  if (!f || !f.moving_gates || !f.still_gates) {
    g.fillText(f ? "basic mode: no gate energies (enable engineering mode)" : "no frame yet", BARS.left, H / 2);
    return;
  }
  const geo = barGeometry(W, H);
  g.strokeStyle = "#2c323c"; g.lineWidth = 1;
  for (const e of [0, 50, 100]) {
    const y = geo.base - (e / 100) * geo.ph;
    g.beginPath(); g.moveTo(BARS.left, y); g.lineTo(W - BARS.right, y); g.stroke();
    g.fillText(String(e), 4, y + 6);
  }
  for (let gate = 0; gate < 9; gate++) {
    for (const [which, arr, color] of [[0, f.moving_gates, "#f0883e"], [1, f.still_gates, "#58a6ff"]]) {
      const e = arr[gate] || 0, h = (e / 100) * geo.ph;
      g.fillStyle = color; g.fillRect(geo.x(gate, which), geo.base - h, geo.bw, h);
    }
    g.fillStyle = "#8b93a0"; g.fillText(String(gate), BARS.left + gate * geo.slot + geo.slot * 0.4, H - 6);
  }
}
window.dashBars = barGeometry;  // tests read bar heights from the canvas with it

// --- controller and nodes ----------------------------------------------------------------
function showController() {
  const c = D.controller;
  if (!c) return;
  badge($("phase"), c.phase, c.phase === "engaged" ? "ok" : c.phase === "idle" ? "" : "warn");
  put($("c-phase"), `${c.phase}${c.in_range ? ", in range" : ""}${c.face_visible ? ", face seen" : ""}`);
  put($("c-visit"), String(c.visit));
  put($("c-greeted"), c.greeted ? "yes" : "no");
  put($("c-sound"), (c.sound || "none") + (c.farewell_pending ? " (farewell pending)" : ""));
  let waiting = c.waiting;
  if (c.waiting_s > 0) {
    const left = Math.max(0, c.waiting_s - (nowS() - c.stamp_ns / 1e9));
    waiting += `, ${left.toFixed(1)} s left`;
  }
  put($("c-waiting"), waiting);
  put($("c-greeting"), ago(c.last_greeting_ns));
  put($("c-farewell"), ago(c.last_farewell_ns));
}
function showNodes() {
  const body = $("nodes").querySelector("tbody");
  body.textContent = "";
  for (const n of D.nodes || []) {
    const tr = document.createElement("tr");
    tr.dataset.node = n.name;
    const cells = [
      [n.name, ""], [n.alive ? "alive" : "down", n.alive ? "alive" : "down"], [String(n.restarts), "num"],
      [n.level || "–", n.level ? "lvl-" + n.level : ""], [n.message || "", "msg"],
    ];
    for (const [text, cls] of cells) {
      const td = document.createElement("td"); td.textContent = text; td.className = cls; tr.appendChild(td);
    }
    tr.firstChild.title = n.name;  // a long name is cut to its column
    tr.title = n.message || "";
    body.appendChild(tr);
  }
}

// --- operator control and leases --------------------------------------------------------
// The buttons act under the dashboard's operator lease only: until the operator
// takes control they are disabled and their tooltip says why, so a press never
// takes the robot from its own behaviour or an app by surprise.
const GAZE = { left: [-0.5, 0], right: [0.5, 0], up: [0, 0.35], down: [0, -0.35], centre: [0, 0] };
const NEEDS_CONTROL = "take control first (the switch above): the robot's own behaviour or an app drives now";
const VIEWER_ONLY = "logged in as a viewer: you may watch, only an operator may press";
for (const b of document.querySelectorAll("#gaze-buttons button")) {
  b.dataset.title = b.title;
  const [yaw, pitch] = GAZE[b.dataset.gaze];
  b.onclick = () => send({ op: "gaze", yaw, pitch });
}
$("control").onchange = (ev) => {
  send({ op: "control", on: ev.target.checked });
  showControl();  // back to what the server says until it answers
};
function showControl() {
  const l = D.leases || { known: false, holding: false };
  const holding = !!l.holding;
  $("control").checked = holding;
  const el = $("control-state");
  el.title = holding ? `this dashboard's operator lease ${l.own}` : "";
  if (holding) put(el, "on: you drive");
  else if (!l.known) put(el, "no lease state: is the eyes driver running?");
  else put(el, "off: buttons locked");
  el.className = holding ? "holding" : "dim";
  for (const b of document.querySelectorAll(".needs-control button")) {
    b.disabled = !holding || D.viewer;
    b.title = D.viewer ? VIEWER_ONLY : holding ? (b.dataset.title || "") : NEEDS_CONTROL;
  }
}
function until(t) {
  if (t === null || t === undefined) return "until released";
  const s = t - nowS();
  return s <= 0 ? "expiring" : s < 90 ? `expires in ${s.toFixed(0)} s` : `expires in ${(s / 60).toFixed(1)} min`;
}
function showLeases() {
  const l = D.leases;
  if (!l) return;
  const box = $("leases");
  box.textContent = "";
  if (!l.known || !l.leases.length) {
    const div = document.createElement("div");
    div.className = "none";
    div.textContent = l.known ? "none: the robot's own behaviour holds everything"
      : "no leases/state from the eyes driver (not running?)";
    box.appendChild(div);
  }
  for (const lease of l.leases) {
    const div = document.createElement("div");
    div.className = "lease" + (lease.own ? " own" : "");
    div.dataset.lease = lease.lease_id;
    div.title = `lease ${lease.lease_id}` + (lease.own ? " (this dashboard's: you)" : "");
    div.innerHTML = `<div class="l1"><b class="holder"></b><span class="prio"></span><button class="break">Break</button></div>`
      + `<div class="l2"><span class="res"></span> · since <span class="since"></span> · <span class="expires"></span></div>`;
    div.querySelector(".holder").textContent = lease.holder + (lease.own ? " (you)" : "");
    const prio = div.querySelector(".prio");
    prio.textContent = lease.priority; prio.className = "prio prio-" + lease.priority;
    div.querySelector(".res").textContent = lease.resources.join(", ");
    div.querySelector(".since").textContent = ago(lease.since * 1e9);
    div.querySelector(".expires").textContent = until(lease.expires);
    const b = div.querySelector("button");
    b.dataset.break = lease.lease_id;
    b.title = `end ${lease.holder}'s lease now (leases/release, "broken by operator")`;
    b.onclick = () => send({ op: "break", lease_id: lease.lease_id });
    box.appendChild(div);
  }
  const ended = $("leases-ended");
  ended.textContent = "";
  for (const e of l.ended.slice(0, 4)) {
    const div = document.createElement("div");
    div.dataset.ended = e.lease_id;
    div.innerHTML = `ended <span class="reason"></span> · <b></b> <span class="when"></span> <span class="msg"></span>`;
    div.querySelector(".reason").textContent = e.reason;
    div.querySelector("b").textContent = e.holder;
    div.querySelector(".when").textContent = ago(e.t * 1e9);
    div.querySelector(".msg").textContent = e.message ? "— " + e.message : "";
    div.title = `lease ${e.lease_id}: ${e.reason}${e.message ? " (" + e.message + ")" : ""}`;
    ended.appendChild(div);
  }
}
// "since" and "expires" move on: their cells only (a rebuilt row would swallow a click).
setInterval(() => {
  for (const lease of (D.leases && D.leases.leases) || []) {
    const tr = document.querySelector(`#leases div[data-lease="${CSS.escape(lease.lease_id)}"]`);
    if (!tr) continue;
    put(tr.querySelector(".since"), ago(lease.since * 1e9));
    put(tr.querySelector(".expires"), until(lease.expires));
  }
  for (const e of (D.leases && D.leases.ended) || []) {
    const div = document.querySelector(`#leases-ended div[data-ended="${CSS.escape(e.lease_id)}"]`);
    if (div) put(div.querySelector(".when"), ago(e.t * 1e9));
  }
}, 1000);

// --- known people (identity) -------------------------------------------------------------
// Remembering a face and forgetting one act under the operator lease only (the
// buttons are "needs-control"); the list is asked for when the page connects.
$("enrol").dataset.title = $("enrol").getAttribute("data-title");
$("enrol").onclick = () => {
  const name = $("enrol-name").value.trim();
  if (!name) { showReply({ ok: false, text: "type their name first" }); return; }
  showReply({ ok: true, text: `look at the camera, ${name}…` });
  send({ op: "enrol", name });
};
function showKnown() {
  const v = D.known, box = $("known");
  box.textContent = "";
  if (!v.known || !v.people.length) {
    const div = document.createElement("div");
    div.className = "none";
    div.textContent = v.known ? "nobody enrolled" : v.error;
    box.appendChild(div);
  }
  for (const p of v.people) {
    const div = document.createElement("div");
    div.className = "known-row"; div.dataset.name = p.name;
    div.innerHTML = `<b class="name"></b><span class="seen"></span><button class="forget">Forget</button>`;
    div.querySelector(".name").textContent = p.name;
    div.querySelector(".seen").textContent = p.last_seen ? "seen " + ago(p.last_seen * 1e9) : "not seen since enrolled";
    const b = div.querySelector("button");
    b.dataset.title = `erase ${p.name}'s face templates now (identity/forget)`;
    b.onclick = () => send({ op: "forget", name: p.name });
    box.appendChild(div);
  }
  showControl();
}
function showPresent(people) {
  const el = $("present-names");
  el.textContent = "";
  if (!people.length) { el.textContent = "nobody present"; return; }
  el.append("present: ");
  people.forEach((p, i) => {
    if (i) el.append(", ");
    const b = document.createElement(p.name ? "b" : "span");
    b.textContent = `person ${p.id} ` + (p.name || "(not recognised)");
    el.append(b);
  });
}

showControl();
connect();
