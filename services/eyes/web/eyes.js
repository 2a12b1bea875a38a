// BuddyBot eyes: draws one or both eyes on a canvas, fed over a WebSocket.
//
// Page: /eyes?eye=left|right|both   (debug/test switches: blink=0, saccade=0)
// The server pushes {"topic": T, "msg": M} where M has the contract's field
// names (docs/design.md section 3): direction {yaw, pitch} degrees (+yaw = robot's
// left), pupil {dilation_percentage}, lids {eye_id 0 L/1 R/2 both,
// top_lid_position, bottom_lid_position}, expression {action}, plus
// hello {iris_color, max_yaw_deg, max_pitch_deg, style}, status {bus},
// motion {kind, start_ms, duration_ms, params} and pong {t0, server_ms}.
//
// Every value eases toward its target once per animation frame (exponential
// approach, frame-rate independent; an expression and its lids as one pose
// change, pose.js), so a new target never makes a jump.
// One face, many screens: the page decides no blink or saccade itself. The
// renderer decides them once for every page (motion events, start times on
// the server clock); the page learns the server clock (ping/pong, NTP-style,
// the sample with the smallest round trip) and draws each event at
// server time = performance.timeOrigin + performance.now() + offset, so
// two screens blink in the same frame. It reconnects by itself when the
// server goes away. Until it is "ready" (its WebSocket is open and the
// renderer is on the bus, so state can arrive) it shows a calm
// "connecting" face: eyes half closed, looking ahead, dimmed.
//
// How the eyes look is the style's (pose.js eases between its key poses,
// draw.js draws a frame); the hello carries the style and a new hello
// restyles the page in place. direction may carry target_distance_cm: a
// person close by makes the eyes converge (vergence), unknown = none.
"use strict";

(() => {
  const params = new URLSearchParams(location.search);
  const which = ["left", "right", "both"].includes(params.get("eye")) ? params.get("eye") : "both";
  const autoBlink = params.get("blink") !== "0";
  const autoSaccade = params.get("saccade") !== "0";

  const EXPR = { AWAKE: 0, SLEEP: 1, SLEEPY: 2, GRIN: 3, SAD: 4, LOOK_RANDOM: 5, LOVE: 6, STAR: 7,
    ALERT: 8 };
  const EXPRESSIONS = Object.keys(EXPR).length;
  const { EyePose, EyeDraw } = window;

  const cfg = { iris: "#2f7fd0", maxYaw: 40, maxPitch: 30, style: EyePose.FALLBACK };

  // Time constants (s) of the exponential approach toward targets.
  const TAU = { gaze: 0.045, pupil: 0.25, shape: 0.15, calm: 0.3, verge: 0.25 };
  // Vergence: none beyond this distance, the most at NEAR_CM and closer.
  const VERGE_FAR_CM = 150;
  const VERGE_NEAR_CM = 30;
  const BLINK_CLOSE_MS = 60;     // blinkNow() (debug): closing ~50-70 ms like a real blink
  const BLINK_OPEN_MS = 160;     // ... reopening slower
  const CLOCK_BURST = 8;         // pings right after connecting, 60 ms apart
  const CLOCK_EVERY_MS = 2000;   // then one every 2 s (drift, a better round trip)
  const CLOCK_KEEP = 20;         // the best of the last 20 samples counts
  const now = () => performance.now();
  const epochMs = () => performance.timeOrigin + performance.now();
  // The server clock (ms since the epoch) at page time t (performance.now() domain).
  const clock = { offset: 0, rtt: -1, samples: [], synced: false };
  const serverTime = (t) => performance.timeOrigin + t + clock.offset;

  const target = {
    yaw: 0, pitch: 0, dilation: 50, expression: EXPR.AWAKE, distance: null,
    lids: { left: { top: 0, bottom: 0 }, right: { top: 0, bottom: 0 } },
  };
  const cur = {
    yaw: 0, pitch: 0, dilation: 50,
    lids: { left: { top: 0, bottom: 0 }, right: { top: 0, bottom: 0 } },
    sad: 0, grin: 0, love: 0, star: 0,   // how far each expression's shape is in (0..1)
    calm: 1,                     // 1 = the connecting face, 0 = normal eyes
    verg: 0,                     // vergence, 0 (far or unknown) .. 1 (near)
    rest: 0,                     // asleep: 1 = the eyes rest in the middle, whatever the gaze
    pose: EyePose.target(EyePose.FALLBACK, EXPR.AWAKE, "#2f7fd0"),   // the eased pose drawn
    poseT: 1,                    // progress of the pose change under way (1: arrived)
    poseTo: EXPR.AWAKE,          // ... and the expression it goes to
    spinAngle: 0,                // radians a spinning shape (a star) has turned
  };

  // Debug/benchmark surface (read by the tests and benchmarks/eyes.py).
  const eyes = {
    which, target, cur, cfg, connected: false, bus: false, ready: false,
    stats: { frames: 0, messages: 0, badMessages: 0, connects: 0, blinks: 0, motions: 0 },
    clock,                       // {offset ms: server - page clock, rtt ms of that sample, ...}
    serverTime: () => serverTime(now()),
    // Last 50 blinks as drawn: start_ms (page clock) and server_ms (server clock)
    // of the first frame drawn with it, event_ms (its start as decided), recv_ms
    // (when it arrived, server clock), close_ms and open_ms (measured at frame
    // granularity).
    blinkLog: [],
    saccadeLog: [],              // last 50 saccades: {event_ms, server_ms, yaw, pitch, ...}
    frameIntervals: [],          // last 1200 requestAnimationFrame intervals, ms
    drawTimes: [],               // last 1200 per-frame update+draw costs, ms
    latency: [],                 // {stamp_ns, recv_ms, frame_ms} per direction message
    blinkNow: () => addBlink({ kind: "blink", start_ms: serverTime(now()),
      duration_ms: BLINK_CLOSE_MS + BLINK_OPEN_MS,
      params: { close_ms: BLINK_CLOSE_MS, open_ms: BLINK_OPEN_MS, cause: "debug" } }),
    receive: (text) => onMessage(text),   // feed a server message by hand (devtools, tests)
    vergenceGoal: () => vergenceGoal(),   // the vergence the page eases toward (tests)
  };
  window.eyes = eyes;

  // --- messages --------------------------------------------------------------------
  let lastGazeMsg = -1e9;
  let pendingLatency = null;

  function setLids(eyeId, top, bottom) {
    const lids = { top: clamp(top, 0, 100), bottom: clamp(bottom, 0, 100) };
    if (eyeId === 0 || eyeId === 2) target.lids.left = { ...lids };
    if (eyeId === 1 || eyeId === 2) target.lids.right = { ...lids };
  }

  function apply(topic, msg) {
    switch (topic) {
      case "direction":
        if (!isNum(msg.yaw) || !isNum(msg.pitch)) return false;
        target.yaw = msg.yaw;
        target.pitch = msg.pitch;
        target.distance = isNum(msg.target_distance_cm) && msg.target_distance_cm > 0
          ? msg.target_distance_cm : null;
        lastGazeMsg = now();
        pendingLatency = { stamp_ns: msg.stamp_ns, recv_ms: epochMs(), frame_ms: 0 };
        return true;
      case "pupil":
        if (!isNum(msg.dilation_percentage)) return false;
        target.dilation = clamp(msg.dilation_percentage, 0, 100);
        return true;
      case "lids":
        if (![0, 1, 2].includes(msg.eye_id)) return false;
        if (!isNum(msg.top_lid_position) || !isNum(msg.bottom_lid_position)) return false;
        setLids(msg.eye_id, msg.top_lid_position, msg.bottom_lid_position);
        return true;
      case "expression":
        if (!Number.isInteger(msg.action) || msg.action < 0 || msg.action >= EXPRESSIONS) return false;
        target.expression = msg.action;
        return true;
      case "status":
        if (typeof msg.bus !== "boolean") return false;
        eyes.bus = msg.bus;
        updateReady();
        return true;
      case "motion":
        return takeMotion(msg);
      case "pong":
        return takePong(msg);
      case "hello":
        if (msg.style != null && !EyePose.isStyle(msg.style)) return false;
        if (msg.style != null) cfg.style = msg.style;
        if (typeof msg.iris_color === "string") cfg.iris = msg.iris_color;
        if (isNum(msg.max_yaw_deg) && msg.max_yaw_deg > 0) cfg.maxYaw = msg.max_yaw_deg;
        if (isNum(msg.max_pitch_deg) && msg.max_pitch_deg > 0) cfg.maxPitch = msg.max_pitch_deg;
        return true;
      default:
        return false;
    }
  }

  function onMessage(text) {
    let data;
    try {
      data = JSON.parse(text);
    } catch (err) {
      eyes.stats.badMessages++;
      return;
    }
    if (!data || typeof data !== "object" || !data.msg || typeof data.msg !== "object"
        || !apply(data.topic, data.msg)) {
      eyes.stats.badMessages++;
      return;
    }
    eyes.stats.messages++;
  }

  // --- connection: reconnect forever with a short backoff ----------------------------
  const statusDot = document.getElementById("status");
  let retryMs = 200;

  function updateReady() {
    eyes.ready = eyes.connected && eyes.bus;
    statusDot.classList.toggle("offline", !eyes.ready);
    statusDot.title = !eyes.connected ? "not connected to the eye renderer"
      : (eyes.bus ? "connected" : "the eye renderer is waiting for the robot's bus");
  }

  function connect() {
    const proto = location.protocol === "https:" ? "wss:" : "ws:";
    const ws = new WebSocket(`${proto}//${location.host}/ws?eye=${which}`);
    let pinger = null;
    ws.onopen = () => {
      eyes.connected = true;
      eyes.stats.connects++;
      retryMs = 200;
      updateReady();             // still "connecting" until the renderer says it is on the bus
      // A new connection may be another server (a restarted renderer):
      // start the estimate afresh (the old offset stays until a new sample).
      clock.samples.length = 0;
      let sent = 0;
      const ping = () => {
        if (ws.readyState !== WebSocket.OPEN) return;
        ws.send(JSON.stringify({ topic: "ping", msg: { t0: now() } }));
        sent++;
        pinger = setTimeout(ping, sent < CLOCK_BURST ? 60 : CLOCK_EVERY_MS);
      };
      ping();
    };
    ws.onmessage = (ev) => onMessage(ev.data);
    ws.onclose = () => {
      clearTimeout(pinger);
      eyes.connected = false;
      eyes.bus = false;          // the next hello batch says again
      updateReady();
      setTimeout(connect, retryMs);
      retryMs = Math.min(retryMs * 2, 2000);
    };
    ws.onerror = () => ws.close();
  }

  // --- the server clock: NTP-style, the sample with the smallest round trip ----------
  function takePong(msg) {
    if (!isNum(msg.t0) || !isNum(msg.server_ms)) return false;
    const t1 = now();
    const rtt = t1 - msg.t0;
    if (rtt < 0 || rtt > 10000) return false;
    // The server read its clock about halfway through the round trip.
    const offset = msg.server_ms - (performance.timeOrigin + (msg.t0 + t1) / 2);
    clock.samples.push({ rtt, offset });
    if (clock.samples.length > CLOCK_KEEP) clock.samples.shift();
    let best = clock.samples[0];
    for (const sample of clock.samples) if (sample.rtt < best.rtt) best = sample;
    clock.offset = best.offset;
    clock.rtt = best.rtt;
    clock.synced = true;
    return true;
  }

  // --- motion decided by the renderer: blinks and saccades --------------------------
  // Events are kept in start order; each is drawn at its server time. Saccades
  // move an offset added to the commanded direction, from (from_yaw,
  // from_pitch) to (yaw, pitch), so a page that missed earlier ones still
  // draws the same motion; a page that connects late gets the newest of each
  // kind with the state and joins the motion under way.
  const blinks = [];             // pending and running blink events
  const saccades = [];           // pending saccades plus the last one started
  let drawnBlink = null;         // {ev, start_ms, server_ms, closedAt}
  const offset = { yaw: 0, pitch: 0 };
  eyes.offset = offset;          // the saccade offset drawn (degrees), for tests

  function takeMotion(msg) {
    if (!["blink", "saccade"].includes(msg.kind) || !isNum(msg.start_ms)
        || !isNum(msg.duration_ms) || msg.duration_ms < 0 || msg.duration_ms > 10000
        || !msg.params || typeof msg.params !== "object") return false;
    const p = msg.params;
    msg.recv_ms = serverTime(now());   // how early it arrived (logged with it)
    if (msg.kind === "blink") {
      if (!isNum(p.close_ms) || !isNum(p.open_ms) || p.close_ms <= 0 || p.open_ms <= 0) {
        return false;
      }
      eyes.stats.motions++;
      if (autoBlink) addBlink(msg);
      return true;
    }
    if (!["from_yaw", "from_pitch", "yaw", "pitch"].every((k) => isNum(p[k]))) return false;
    eyes.stats.motions++;
    if (autoSaccade) addSaccade(msg);
    return true;
  }

  function insertByStart(list, ev) {
    // The same event again (a reconnect replays the state): kept once.
    if (list.some((x) => x.start_ms === ev.start_ms)) return;
    list.push(ev);
    list.sort((a, b) => a.start_ms - b.start_ms);
  }

  function addBlink(ev) {
    insertByStart(blinks, ev);
    if (blinks.length > 20) blinks.shift();
  }

  function addSaccade(ev) {
    insertByStart(saccades, ev);
    if (saccades.length > 20) saccades.shift();
  }

  function blinkAmount(t) {
    const st = serverTime(t);
    while (blinks.length && st >= blinks[0].start_ms + blinks[0].duration_ms) {
      const done = blinks.shift();
      if (drawnBlink && drawnBlink.ev === done) finishBlink(st);
    }
    const ev = blinks.length && st >= blinks[0].start_ms ? blinks[0] : null;
    if (!ev) return 0;
    const e = st - ev.start_ms;
    if (!drawnBlink || drawnBlink.ev !== ev) {
      drawnBlink = { ev, start_ms: t, server_ms: st, closedAt: -1 };
    }
    const close = ev.params.close_ms;
    const open = ev.params.open_ms;
    if (e < close) return easeIn(e / close);
    if (drawnBlink.closedAt < 0) drawnBlink.closedAt = e;   // first frame past full closure
    return 1 - easeOut(Math.min(1, (e - close) / open));
  }

  function finishBlink(st) {
    const b = drawnBlink;
    drawnBlink = null;
    const e = st - b.ev.start_ms;
    eyes.blinkLog.push({ start_ms: b.start_ms, server_ms: b.server_ms, event_ms: b.ev.start_ms,
      recv_ms: b.ev.recv_ms,
      close_ms: b.closedAt, open_ms: b.closedAt < 0 ? -1 : e - b.closedAt,
      cause: b.ev.params.cause });
    if (eyes.blinkLog.length > 50) eyes.blinkLog.shift();
    eyes.stats.blinks++;
  }

  function updateOffset(t) {
    const st = serverTime(t);
    while (saccades.length > 1 && st >= saccades[1].start_ms) saccades.shift();
    if (!saccades.length) return;
    const ev = saccades[0];
    const p = ev.params;
    if (st < ev.start_ms) {          // not started yet: still where it starts from
      offset.yaw = p.from_yaw;
      offset.pitch = p.from_pitch;
      return;
    }
    if (!ev.drawn) {
      ev.drawn = true;
      eyes.saccadeLog.push({ event_ms: ev.start_ms, server_ms: st, recv_ms: ev.recv_ms,
        yaw: p.yaw, pitch: p.pitch,
        duration_ms: ev.duration_ms, purpose: p.purpose });
      if (eyes.saccadeLog.length > 50) eyes.saccadeLog.shift();
    }
    // Smooth start and stop, all within the event's main-sequence duration.
    const k = ev.duration_ms > 0 ? clamp((st - ev.start_ms) / ev.duration_ms, 0, 1) : 1;
    const s = 0.5 - 0.5 * Math.cos(Math.PI * k);
    offset.yaw = p.from_yaw + (p.yaw - p.from_yaw) * s;
    offset.pitch = p.from_pitch + (p.pitch - p.from_pitch) * s;
  }

  // --- animation ---------------------------------------------------------------------
  const canvas = document.getElementById("eyes");
  const ctx = canvas.getContext("2d", { alpha: false });
  let lastFrame = 0;
  const base = { yaw: 0, pitch: 0 };   // the commanded direction, eased
  eyes.base = base;              // read-only, for tests and benchmarks (drawn: base + offset)

  function resize() {
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(window.innerWidth * dpr));
    const h = Math.max(1, Math.round(window.innerHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) {
      canvas.width = w;
      canvas.height = h;
    }
  }

  function approach(value, goal, tau, dt) {
    return value + (goal - value) * (1 - Math.exp(-dt / tau));
  }

  // A new expression, its lids, style or iris colour: ease every pose number
  // from where it is now to the new pose over the pose's transition time. The
  // driver sends the lids and the expression as two messages a moment apart:
  // the second restarts the move from where the first has got (nearly nowhere,
  // the ease starts slowly), so they move as one.
  const poseMove = { key: "", from: cur.pose, to: cur.pose, t0: 0, ms: 0 };
  function updatePose(t, dt) {
    const L = target.lids;
    const key = `${cfg.style.name}|${target.expression}|${cfg.iris}|${L.left.top}|`
      + `${L.left.bottom}|${L.right.top}|${L.right.bottom}`;
    if (key !== poseMove.key || cfg.style !== poseMove.style) {
      poseMove.key = key;
      poseMove.style = cfg.style;
      poseMove.from = cur.pose;
      poseMove.to = EyePose.target(cfg.style, target.expression, cfg.iris, L);
      poseMove.t0 = t;
      poseMove.ms = EyePose.duration(cfg.style, target.expression);
      cur.poseTo = target.expression;
    }
    const k = poseMove.ms > 0 ? clamp((t - poseMove.t0) / poseMove.ms, 0, 1) : 1;
    const P = cur.pose = k >= 1 ? poseMove.to
      : EyePose.lerp(poseMove.from, poseMove.to, EyePose.ease(k));
    cur.poseT = k;
    cur.lids.left.top = P.lid_lt;
    cur.lids.left.bottom = P.lid_lb;
    cur.lids.right.top = P.lid_rt;
    cur.lids.right.bottom = P.lid_rb;
    cur.spinAngle = (cur.spinAngle + (P.spin * Math.PI / 180) * dt) % (2 * Math.PI);
  }

  // 0 beyond VERGE_FAR_CM or with no distance, 1 at VERGE_NEAR_CM and nearer.
  function vergenceGoal() {
    if (!eyes.ready || target.distance === null) return 0;
    return clamp((VERGE_FAR_CM - target.distance) / (VERGE_FAR_CM - VERGE_NEAR_CM), 0, 1);
  }

  function step(t) {
    const dt = lastFrame ? Math.min((t - lastFrame) / 1000, 0.1) : 0;
    if (lastFrame) {
      const iv = eyes.frameIntervals;
      iv.push(t - lastFrame);
      if (iv.length > 1200) iv.shift();
    }
    lastFrame = t;
    const work0 = now();
    updateOffset(t);
    // Connecting: look straight ahead (no stale gaze at someone who left).
    const yawGoal = eyes.ready ? target.yaw : 0;
    const pitchGoal = eyes.ready ? target.pitch : 0;
    cur.calm = approach(cur.calm, eyes.ready ? 0 : 1, TAU.calm, dt);
    base.yaw = approach(base.yaw, yawGoal, TAU.gaze, dt);
    base.pitch = approach(base.pitch, pitchGoal, TAU.gaze, dt);
    // The saccade offset is drawn as decided (its own timing), faded out
    // while connecting.
    cur.yaw = base.yaw + offset.yaw * (1 - cur.calm);
    cur.pitch = base.pitch + offset.pitch * (1 - cur.calm);
    cur.dilation = approach(cur.dilation, target.dilation, TAU.pupil, dt);
    const ex = target.expression;
    updatePose(t, dt);
    cur.verg = approach(cur.verg, vergenceGoal(), TAU.verge, dt);
    cur.rest = approach(cur.rest, ex === EXPR.SLEEP ? 1 : 0, TAU.calm, dt);
    cur.sad = approach(cur.sad, ex === EXPR.SAD ? 1 : 0, TAU.shape, dt);
    cur.grin = approach(cur.grin, ex === EXPR.GRIN ? 1 : 0, TAU.shape, dt);
    cur.love = approach(cur.love, ex === EXPR.LOVE ? 1 : 0, TAU.shape, dt);
    cur.star = approach(cur.star, ex === EXPR.STAR ? 1 : 0, TAU.shape, dt);
    const blink = blinkAmount(t);
    draw(t, blink);
    eyes.drawTimes.push(now() - work0);
    if (eyes.drawTimes.length > 1200) eyes.drawTimes.shift();
    eyes.stats.frames++;
    if (pendingLatency) {        // first frame drawn with the new gaze target
      pendingLatency.frame_ms = epochMs();
      eyes.latency.push(pendingLatency);
      if (eyes.latency.length > 1000) eyes.latency.shift();
      pendingLatency = null;
    }
    requestAnimationFrame(step);
  }

  // --- drawing (draw.js) ---------------------------------------------------------------
  // A live restyle to another kind of drawing or background cannot be eased number
  // by number: the last frame of the old look fades out over the new one (not the
  // first style a page gets: the look it had until then was only a stand-in).
  const fade = { canvas: document.createElement("canvas"), look: "", t0: -1, ms: 0 };

  function draw(t, blink) {
    resize();
    const look = cfg.style === EyePose.FALLBACK ? ""
      : `${cfg.style.kind}|${cfg.style.background}`;
    if (fade.look && look !== fade.look) {
      fade.canvas.width = canvas.width;
      fade.canvas.height = canvas.height;
      fade.canvas.getContext("2d").drawImage(canvas, 0, 0);
      fade.t0 = t;
      fade.ms = cfg.style.transition_ms;
    }
    fade.look = look;
    EyeDraw.draw(ctx, canvas.width, canvas.height, {
      which, style: cfg.style, pose: cur.pose, lids: cur.lids, calm: cur.calm, blink,
      // Asleep nothing moves but the breath: the eyes rest in the middle.
      yawN: clamp(cur.yaw / cfg.maxYaw, -1, 1) * (1 - cur.rest),
      pitchN: clamp(cur.pitch / cfg.maxPitch, -1, 1) * (1 - cur.rest),
      verg: cur.verg * (1 - cur.rest), dilation: cur.dilation, spinAngle: cur.spinAngle,
      // Breath and heartbeat on the server clock: two screens breathe together.
      t: serverTime(t),
    });
    if (fade.t0 >= 0) {
      const k = fade.ms > 0 ? (t - fade.t0) / fade.ms : 1;
      if (k >= 1) fade.t0 = -1;
      else {
        ctx.globalAlpha = 1 - EyePose.ease(k);
        ctx.drawImage(fade.canvas, 0, 0);
        ctx.globalAlpha = 1;
      }
    }
  }

  // --- helpers -----------------------------------------------------------------------
  function clamp(v, lo, hi) { return Math.min(hi, Math.max(lo, v)); }
  function isNum(v) { return typeof v === "number" && Number.isFinite(v); }
  function easeIn(p) { return p * p; }
  function easeOut(p) { return 1 - (1 - p) * (1 - p); }

  window.addEventListener("resize", resize);
  updateReady();
  connect();
  requestAnimationFrame(step);
})();
