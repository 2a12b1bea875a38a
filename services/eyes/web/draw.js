// BuddyBot eyes: drawing one frame of the face from the eased state.
//
// Two kinds of style (services/eyes/styles.py): "glow", a rounded glowing
// shape per eye that moves as a whole and whose lids cut it (a closed eye
// is a thin glowing line), with a dark pupil in a bright core; and
// "eyeball", a white ball whose iris moves and whose lids are
// background-coloured caps. Both read the same pose numbers, and both
// pupils are the commanded dilation (eyes/pupil: a near person widens them).
//
// Shared "alive" cues (eyes.js eases their inputs): lids follow the gaze;
// vergence (the eyes turn in for a near person); curiosity (the eye on the
// side looked at grows); squash and stretch (a blinking glow eye gets
// flatter and wider); a slow breath (the glow dims, a drowsy lid sinks).
// The glow's halo is drawn on a canvas 1/8 the size and laid on scaled up.
"use strict";

window.EyeDraw = (() => {
  const REST_LIDS = { top: 30, bottom: 16 };   // the connecting face: half closed
  const REST_DIM = 0.55;                       // ... and dimmed toward the background
  const SCLERA = "#f2f4f8";
  const PUPIL = "#000000";
  const LASH = "#3c4966";                      // lash line of a closed eyeball
  const LASH_LIFT = 0.08;                      // ... lifting this much (of the eye) per breath
  const GLOW_SCALE = 0.125;                    // the glow layer's size, of the canvas
  const GLOW_BLUR = 0.12;                      // halo blur, of the eye's cell
  const GLOW_GAIN = 1.6;                       // halo strength at glow 100
  const BREATH_HZ = 0.25;                      // asleep, drowsy: one slow breath every 4 s
  const LINE_SWELL = 0.8;                      // a shut glow eye's line is this much thicker
                                               // at the top of a full (100 %) breath
  const PUPIL_REACH = 0.6;                     // the glow pupil moves this much of its room
  const PUPIL_TURN_IN = 0.35;                  // ... and this much toward the nose (near)
  const CLOSED_LINE = 0.028;                   // a shut glow eye: a line this thick (of cell)
  const near = document.createElement("canvas");   // glow layer: the shapes, small
  const nearCtx = near.getContext("2d");
  const halo = document.createElement("canvas");   // ... and blurred
  const haloCtx = halo.getContext("2d");

  function clamp(v, lo, hi) { return Math.min(hi, Math.max(lo, v)); }

  // The lids one eye shows, % of its height covered from the top and bottom.
  // `uncut`: a glow heart or star is not cut by its expression's lids (a
  // blink still closes it).
  function lidsOf(s, side, uncut = 0) {
    const P = s.pose;
    const L = s.lids[side];
    // The commanded lids (eyes/lids), at least what the pose asks for; a
    // drowsy top lid sinks with each breath.
    let top = (Math.max(L.top, P.top_lid) + P.sway * exhale(s)) * (1 - uncut);
    let bottom = Math.max(L.bottom, P.bottom_lid) * (1 - uncut);
    // Connecting: at least half closed (a closed eye stays closed).
    top += (Math.max(top, REST_LIDS.top) - top) * s.calm;
    bottom += (Math.max(bottom, REST_LIDS.bottom) - bottom) * s.calm;
    // Lids follow the gaze (not while connecting; a shut eye stays shut).
    const open = clamp(1 - (top + bottom) / 100, 0, 1);
    const follow = s.style.lid_follow * s.pitchN * (1 - s.calm) * open;
    top = clamp(top - follow, 0, 100);
    bottom = clamp(bottom + 0.4 * follow, 0, 100);
    // The part of a blink the lids do (the rest flattens a glow eye: squash).
    const lidBlink = s.blink * (1 - s.style.squash / 100);
    top += (50 - top) * lidBlink;
    bottom += (50 - bottom) * lidBlink;
    if (top + bottom > 100) {
      const k = 100 / (top + bottom);
      top *= k;
      bottom *= k;
    }
    return { top, bottom };
  }

  // Where one eye sits in its cell and how it moves (pixels).
  function layout(s, side, x, y, w, h) {
    const S = Math.min(w, h);
    const st = s.style;
    const awake = 1 - s.calm;
    // +yaw is the robot's left: toward the robot's left eye's side.
    const toward = (side === "left" ? s.yawN : -s.yawN) * awake;
    const grow = 1 + (st.curiosity / 100) * (toward > 0 ? toward : 0.5 * toward);
    // The nose is between the eyes: the robot's left eye (viewer's right) moves -x.
    const nose = side === "left" ? -1 : 1;
    const reach = (st.reach / 100) * S;
    return {
      S, cx: x + w / 2, cy: y + h / 2, grow,
      gx: s.yawN * reach + nose * (st.vergence / 100) * S * s.verg * awake,
      gy: -s.pitchN * reach,
    };
  }

  function colourOf(P, k) {
    return `rgb(${Math.round(P.r * k)},${Math.round(P.g * k)},${Math.round(P.b * k)})`;
  }

  // 0 .. 1 .. 0 over one slow breath, 1 its bottom: dimmest, a drowsy lid lowest
  // (s.t is the server clock: two screens breathe together).
  function exhale(s) { return 0.5 - 0.5 * Math.cos(2 * Math.PI * BREATH_HZ * s.t / 1000); }

  // The brightness a breath leaves (1: none).
  function breath(s) { return 1 - (s.pose.breathe / 100) * exhale(s); }

  // --- shapes ------------------------------------------------------------------------
  // Every shape here is seen whole from its centre (a ray from the centre crosses its
  // outline once), so each is one radius per direction, and a change of shape is a
  // morph: the outline at each of OUTLINE_N directions moves from one shape's to the
  // other's (a rounded eye bends into a heart), never two shapes laid over each other.

  const OUTLINE_N = 120;                       // directions: every 3 degrees
  const COS = Float64Array.from({ length: OUTLINE_N }, (_, k) => Math.cos(dirOf(k)));
  const SIN = Float64Array.from({ length: OUTLINE_N }, (_, k) => Math.sin(dirOf(k)));
  // A heart filling the unit box -0.5..0.5: four cubic curves, end to end.
  const HEART = polarTable(curvePoints([[0, 0.46], [-0.3, 0.24], [-0.52, 0.02], [-0.5, -0.2],
    [-0.48, -0.44], [-0.14, -0.52], [0, -0.26], [0.14, -0.52], [0.48, -0.44], [0.5, -0.2],
    [0.52, 0.02], [0.3, 0.24], [0, 0.46]]));
  // A five-pointed star in the unit box, a point up.
  const STAR = polarTable(starPoints(0.5, 0.22));

  function dirOf(k) { return -Math.PI + (2 * Math.PI * k) / OUTLINE_N; }

  function curvePoints(p) {
    const out = [];
    for (let i = 0; i + 3 < p.length; i += 3) {
      for (let j = 0; j < 200; j++) {
        const t = j / 200;
        const u = 1 - t;
        const w = [u * u * u, 3 * u * u * t, 3 * u * t * t, t * t * t];
        out.push([0, 1].map((d) => w.reduce((acc, wk, n) => acc + wk * p[i + n][d], 0)));
      }
    }
    return out;
  }

  function starPoints(outer, inner) {
    const corner = (i) => {
      const r = i % 2 === 0 ? outer : inner;
      const a = -Math.PI / 2 + (i * Math.PI) / 5;
      return [r * Math.cos(a), r * Math.sin(a)];
    };
    const out = [];
    for (let i = 0; i < 10; i++) {
      const [a, b] = [corner(i), corner(i + 1)];
      for (let j = 0; j < 100; j++) {
        const t = j / 100;
        out.push([a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]);
      }
    }
    return out;
  }

  // A dense outline around (0, 0) -> its radius in each of the OUTLINE_N directions.
  function polarTable(points) {
    const byDir = points.map(([x, y]) => [Math.atan2(y, x), Math.hypot(x, y)])
      .sort((a, b) => a[0] - b[0]);
    const first = byDir[0];
    const last = byDir[byDir.length - 1];
    const table = new Float64Array(OUTLINE_N);
    let j = 0;
    for (let k = 0; k < OUTLINE_N; k++) {
      const a = dirOf(k);
      while (j < byDir.length && byDir[j][0] < a) j++;
      const lo = j > 0 ? byDir[j - 1] : [last[0] - 2 * Math.PI, last[1]];
      const hi = j < byDir.length ? byDir[j] : [first[0] + 2 * Math.PI, first[1]];
      table[k] = lo[1] + (hi[1] - lo[1]) * ((a - lo[0]) / Math.max(1e-9, hi[0] - lo[0]));
    }
    return table;
  }

  // Where the ray from the centre along (dx, dy) leaves a rounded rectangle of half
  // sizes a, b and corner radius r.
  function rectPoint(a, b, r, dx, dy) {
    const n = Math.hypot(dx, dy) || 1;
    dx /= n;
    dy /= n;
    let t = Math.min(a / Math.max(1e-9, Math.abs(dx)), b / Math.max(1e-9, Math.abs(dy)));
    if (Math.abs(t * dx) > a - r && Math.abs(t * dy) > b - r) {       // a corner's arc
      const ox = Math.sign(dx) * (a - r);
      const oy = Math.sign(dy) * (b - r);
      const along = dx * ox + dy * oy;
      t = along + Math.sqrt(Math.max(0, along * along - ox * ox - oy * oy + r * r));
    }
    return [t * dx, t * dy];
  }

  function roundRect(c, x, y, w, h, r) {
    r = clamp(r, 0, Math.min(w, h) / 2);
    c.moveTo(x + r, y);
    c.arcTo(x + w, y, x + w, y + h, r);
    c.arcTo(x + w, y + h, x, y + h, r);
    c.arcTo(x, y + h, x, y, r);
    c.arcTo(x, y, x + w, y, r);
    c.closePath();
  }

  // The outline of a mix of shapes around (cx, cy), as a path: weight `plain` of a
  // rounded rectangle w x h with corner radius r, `heart` of a heart filling
  // hw x hh, `star` of a star filling sw x sh and turned by `spin` radians (the
  // weights add up to 1). Only the plain shape: its exact arcs.
  function shapePath(c, cx, cy, m) {
    const r = clamp(m.r, 0, Math.min(m.w, m.h) / 2);
    c.beginPath();
    if (m.heart + m.star < 0.001) {
      roundRect(c, cx - m.w / 2, cy - m.h / 2, m.w, m.h, r);
      return;
    }
    // The star's own directions turn with it, so its points stay sharp as it spins.
    const sc = Math.cos(m.spin);
    const ss = Math.sin(m.spin);
    for (let k = 0; k < OUTLINE_N; k++) {
      let x = 0;
      let y = 0;
      if (m.plain > 0) {
        const [px, py] = rectPoint(m.w / 2, m.h / 2, r, m.w * COS[k], m.h * SIN[k]);
        x += m.plain * px;
        y += m.plain * py;
      }
      if (m.heart > 0) {
        x += m.heart * HEART[k] * COS[k] * m.hw;
        y += m.heart * HEART[k] * SIN[k] * m.hh;
      }
      if (m.star > 0) {
        const ux = STAR[k] * COS[k];
        const uy = STAR[k] * SIN[k];
        x += m.star * (ux * sc - uy * ss) * m.sw;
        y += m.star * (ux * ss + uy * sc) * m.sh;
      }
      if (k === 0) c.moveTo(cx + x, cy + y);
      else c.lineTo(cx + x, cy + y);
    }
    c.closePath();
  }

  // --- glow --------------------------------------------------------------------------

  // One glow eye on context `c`: the shape, cut by the lids, and (`pupils`) its
  // pupil.
  function glowEye(c, s, side, L, fill, pupils) {
    const P = s.pose;
    const st = s.style;
    const lids = lidsOf(s, side, clamp(P.heart + P.star, 0, 1));
    const squash = s.blink * (st.squash / 100);
    const ew = (L.S * P.width / 100) * L.grow * (1 + s.blink * (st.stretch / 100));
    // Asleep the line swells a little as the glow brightens with each breath.
    const line = CLOSED_LINE * L.S * (1 + LINE_SWELL * (P.breathe / 100) * (1 - exhale(s)));
    const eh0 = (L.S * P.height / 100) * L.grow;
    const eh = Math.max(line, eh0 * (1 - squash));
    const cx = L.cx + L.gx;
    const cy = L.cy + L.gy;
    let yT = cy - eh / 2 + (lids.top / 100) * eh;
    let yB = cy + eh / 2 - (lids.bottom / 100) * eh;
    if (yB - yT < line) {          // shut: a thin glowing line, never nothing
      const mid = (yT + yB) / 2;
      yT = mid - line / 2;
      yB = mid + line / 2;
    }
    const open = clamp((yB - yT - line) / Math.max(1, eh - line), 0, 1);
    const half = ew / 2 + L.S * 0.2;
    // Sad/drowsy: the outer corner lower; the slant fades as the eye closes.
    const outer = side === "left" ? 1 : -1;
    const slope = Math.tan((P.top_lid_angle * Math.PI) / 180) * Math.min(1, open * 1.6);
    const yTLeft = yT - outer * slope * half;
    const yTRight = yT + outer * slope * half;
    // Happy: the bottom lid arches up into a crescent.
    const lift = (P.bottom_lid_curve / 100) * 0.5 * eh * open;
    c.save();
    c.beginPath();
    c.moveTo(cx - half, yTLeft);
    c.lineTo(cx + half, yTRight);
    // The arch spans the eye's own width; its feet reach below the lid line.
    const feet = yB + lift * 0.7;
    c.lineTo(cx + half, feet);
    c.lineTo(cx + ew / 2, feet);
    c.quadraticCurveTo(cx, yB - 2 * lift, cx - ew / 2, feet);
    c.lineTo(cx - half, feet);
    c.closePath();
    c.clip();
    // A touch of depth: lit from above, a little darker toward the bottom.
    if (typeof fill === "string") c.fillStyle = fill;
    else {
      const grad = c.createLinearGradient(0, cy - eh / 2, 0, cy + eh / 2);
      grad.addColorStop(0, fill[0]);
      grad.addColorStop(1, fill[1]);
      c.fillStyle = grad;
    }
    // The eye, a heart or a star, or a morph between them (shapePath).
    const plain = clamp(1 - P.heart - P.star, 0, 1);
    const beat = 1 + (P.beat / 100) * Math.max(0, Math.sin(s.t / 1000 * 2 * Math.PI * 1.2)) ** 4;
    shapePath(c, cx, cy, { plain, w: ew, h: eh, r: (P.roundness / 100) * Math.min(ew, eh) / 2,
      heart: P.heart, hw: ew * beat, hh: eh * beat, star: P.star, sw: ew, sh: eh,
      spin: s.spinAngle });
    c.fill();
    if (pupils && plain > 0.01) {
      // The pupil stays inside the eye by itself (its room is the eye's), and
      // within a morph's outline by this clip (only then: a clip costs a fill).
      if (plain < 0.999) c.clip();
      // It fades as the eye shuts (asleep: a line with no pupil) and with the
      // plain eye (a heart or a star has none).
      const seen = clamp(((yB - yT) / Math.max(1, eh0) - 0.12) / 0.25, 0, 1);
      glowPupil(c, s, side, { cx, cy, w: ew, h: eh, h0: eh0 }, plain * seen);
    }
    c.restore();
  }

  // The glow eye's pupil: a dark disc in a bright core (the iris, `iris` % of
  // the eye's width), the commanded dilation of it, kept within 12..92 % so it
  // never vanishes and a ring of core always shows. It moves inside the eye
  // with the gaze (the eye itself moves too) and toward the nose for a near
  // person, and flattens with a blink as the eye does.
  function glowPupil(c, s, side, E, alpha) {
    const P = s.pose;
    const irisR = Math.min((P.iris / 200) * E.w, E.h0 / 2);
    if (irisR < 0.5 || alpha < 0.01) return;
    const pupilR = irisR * clamp((s.dilation / 100) * (P.pupil / 100), 0.12, 0.92);
    const nose = side === "left" ? -1 : 1;
    const roomX = Math.max(0, E.w / 2 - irisR);
    const roomY = Math.max(0, E.h0 / 2 - irisR);
    const x = E.cx + (s.yawN * PUPIL_REACH + nose * s.verg * PUPIL_TURN_IN) * roomX;
    const flat = clamp(E.h / Math.max(1, E.h0), 0, 1);      // a blink flattens it too
    const y = E.cy - s.pitchN * PUPIL_REACH * roomY * flat;
    const k = (P.brightness / 100) * breath(s);
    const [br, bg, bb] = window.EyePose.rgb(s.style.background);
    const core = { r: lighten(P.r, 0.55), g: lighten(P.g, 0.55), b: lighten(P.b, 0.55) };
    const dark = { r: P.r * 0.14 + br * 0.86, g: P.g * 0.14 + bg * 0.86, b: P.b * 0.14 + bb * 0.86 };
    c.save();
    c.globalAlpha = alpha;
    c.translate(x, y);
    c.scale(1, flat);
    const grad = c.createRadialGradient(0, 0, 0, 0, 0, irisR);
    const edge = pupilR / irisR;
    grad.addColorStop(0, colourOf(dark, 1));
    grad.addColorStop(edge * 0.82, colourOf(dark, 1));
    grad.addColorStop(edge, colourOf(core, k));
    grad.addColorStop(edge + (1 - edge) * 0.35, colourOf(core, k));
    grad.addColorStop(1, `rgba(${Math.round(P.r * k)},${Math.round(P.g * k)},${Math.round(P.b * k)},0)`);
    c.fillStyle = grad;
    c.beginPath();
    c.arc(0, 0, irisR, 0, 2 * Math.PI);
    c.fill();
    c.restore();
  }

  function drawGlow(ctx, s, cells, W, H) {
    const P = s.pose;
    const k = (P.brightness / 100) * breath(s);
    const fill = colourOf(P, k);
    const shaded = [colourOf({ r: lighten(P.r, 0.2), g: lighten(P.g, 0.2), b: lighten(P.b, 0.2) }, k),
      colourOf(P, k * 0.8)];
    const strength = (P.glow / 100) * k * GLOW_GAIN;
    if (strength > 0.01) {
      const w = Math.max(1, Math.ceil(W * GLOW_SCALE));
      const h = Math.max(1, Math.ceil(H * GLOW_SCALE));
      if (near.width !== w || near.height !== h) {
        near.width = halo.width = w;
        near.height = halo.height = h;
      }
      nearCtx.setTransform(1, 0, 0, 1, 0, 0);
      nearCtx.clearRect(0, 0, w, h);
      nearCtx.setTransform(GLOW_SCALE, 0, 0, GLOW_SCALE, 0, 0);
      for (const [side, L] of cells) glowEye(nearCtx, s, side, L, fill, false);
      haloCtx.clearRect(0, 0, w, h);
      haloCtx.shadowColor = colourOf(P, 1);
      haloCtx.shadowBlur = GLOW_BLUR * cells[0][1].S * GLOW_SCALE;
      // Above 1 the halo is laid twice, here on the small canvas (canvas alpha
      // stops at 1), so the frame gets one scaled-up copy.
      for (let a = strength; a > 0.01; a -= 1) {
        haloCtx.globalAlpha = clamp(a, 0, 1);
        haloCtx.drawImage(near, 0, 0);
      }
      ctx.imageSmoothingEnabled = true;
      // Only around the eyes (the rest of the halo layer is empty), each pixel
      // once: boxes that overlap are merged.
      const boxes = [];
      for (const [, L] of cells) {
        const r = glowReach(s, L);
        const box = [L.cx + L.gx - r.x, L.cy + L.gy - r.y, L.cx + L.gx + r.x, L.cy + L.gy + r.y];
        const other = boxes.find((b) => b[0] < box[2] && box[0] < b[2] && b[1] < box[3] && box[1] < b[3]);
        if (other) {
          for (const i of [0, 1]) other[i] = Math.min(other[i], box[i]);
          for (const i of [2, 3]) other[i] = Math.max(other[i], box[i]);
        } else boxes.push(box);
      }
      for (const b of boxes) {
        const x0 = clamp(Math.floor(b[0] * GLOW_SCALE), 0, w);
        const y0 = clamp(Math.floor(b[1] * GLOW_SCALE), 0, h);
        const x1 = clamp(Math.ceil(b[2] * GLOW_SCALE), 0, w);
        const y1 = clamp(Math.ceil(b[3] * GLOW_SCALE), 0, h);
        if (x1 > x0 && y1 > y0) {
          ctx.drawImage(halo, x0, y0, x1 - x0, y1 - y0, x0 / GLOW_SCALE, y0 / GLOW_SCALE,
            (x1 - x0) / GLOW_SCALE, (y1 - y0) / GLOW_SCALE);
        }
      }
    }
    for (const [side, L] of cells) glowEye(ctx, s, side, L, shaded, true);
  }

  // Half-sizes (px) of the box an eye's halo can reach from its centre.
  function glowReach(s, L) {
    const P = s.pose;
    const big = 1.1 * L.grow * (1 + s.style.stretch / 100) * (1 + P.beat / 100);
    const margin = 2.5 * GLOW_BLUR * L.S;
    return { x: (L.S * P.width / 200) * big + margin, y: (L.S * P.height / 200) * big + margin };
  }

  function lighten(v, by) { return v + (255 - v) * by; }

  // --- eyeball -----------------------------------------------------------------------

  function eyeballEye(ctx, s, side, L) {
    const P = s.pose;
    const R = (L.S * Math.min(P.width, P.height) / 200) * L.grow;
    const { cx, cy } = L;
    const gx = cx + L.gx;
    const gy = cy + L.gy;
    const irisR = R * (P.iris / 100);
    ctx.save();
    ctx.beginPath();
    ctx.arc(cx, cy, R, 0, 2 * Math.PI);
    ctx.fillStyle = SCLERA;
    ctx.fill();
    ctx.clip();
    // The iris, a heart or a star, or a morph between them (shapePath); the
    // iris's rim and pupil fade as it turns into another shape.
    const plain = clamp(1 - P.heart - P.star, 0, 1);
    const size = Math.max(irisR, R * 0.46) * 2.3;
    const beat = 1 + (P.beat / 100) * Math.sin(s.t / 1000 * 2 * Math.PI * 1.3);
    if (irisR > 0 || plain < 0.99) {
      shapePath(ctx, gx, gy, { plain, w: 2 * irisR, h: 2 * irisR, r: irisR,
        heart: P.heart, hw: size * beat, hh: size * beat, star: P.star, sw: size, sh: size,
        spin: s.spinAngle });
      ctx.fillStyle = colourOf(P, 1);
      ctx.fill();
    }
    if (plain > 0.01 && irisR > 0) {
      ctx.globalAlpha = plain;
      ctx.lineWidth = irisR * 0.08;
      ctx.strokeStyle = "rgba(0,0,0,0.25)";
      ctx.stroke();
      // Dilation is a percentage of the iris, kept within 12..92 % so the
      // pupil never vanishes and a ring of iris always shows.
      const pupilR = irisR * clamp((s.dilation / 100) * (P.pupil / 100), 0.12, 0.92);
      ctx.beginPath();
      ctx.arc(gx, gy, pupilR * plain, 0, 2 * Math.PI);
      ctx.fillStyle = PUPIL;
      ctx.fill();
      ctx.globalAlpha = 1;
    }
    // Catch-light: makes the eye look wet and alive.
    const ir = Math.max(irisR, R * 0.3);
    ctx.beginPath();
    ctx.arc(gx - ir * 0.35, gy - ir * 0.38, ir * 0.16, 0, 2 * Math.PI);
    ctx.fillStyle = "rgba(255,255,255,0.85)";
    ctx.fill();
    ctx.restore();
    eyeballLids(ctx, s, side, cx, cy, R);
  }

  function eyeballLids(ctx, s, side, cx, cy, R) {
    const P = s.pose;
    const { top, bottom } = lidsOf(s, side);
    const span = R * 1.04;
    // Middles of the lid edges; closed lids overlap a little so no seam of
    // sclera shows through the anti-aliasing.
    const yT = cy - span + (top / 50) * (span + R * 0.03);
    const yB = cy + span - (bottom / 50) * (span + R * 0.03);
    const openness = clamp(1 - (top + bottom) / 100, 0, 1);
    const c = R * 0.22 * openness;                 // lid curvature, flat when closed
    const ext = R * 1.3;
    // Sad: outer corners droop. The robot's left eye is on the viewer's right,
    // so its outer corner is at +x; the right eye's outer corner is at -x.
    const outer = side === "left" ? 1 : -1;
    const slant = ext * Math.tan((P.top_lid_angle * Math.PI) / 180) * openness;
    // Lid edges bulge toward the eye's middle (the lid is a cap over a ball).
    const yLeftEnd = yT - c + (outer < 0 ? slant : -slant * 0.5);
    const yRightEnd = yT - c + (outer > 0 ? slant : -slant * 0.5);
    ctx.fillStyle = s.style.background;
    ctx.beginPath();
    ctx.moveTo(cx - ext, cy - ext);
    ctx.lineTo(cx + ext, cy - ext);
    ctx.lineTo(cx + ext, yRightEnd);
    ctx.quadraticCurveTo(cx, yT + c, cx - ext, yLeftEnd);
    ctx.closePath();
    ctx.fill();
    // Grin: the bottom lid bulges up into a happy crescent.
    const lift = R * 0.4 * (P.bottom_lid_curve / 100) * openness;
    ctx.beginPath();
    ctx.moveTo(cx - ext, cy + ext);
    ctx.lineTo(cx + ext, cy + ext);
    ctx.lineTo(cx + ext, yB + c);
    ctx.quadraticCurveTo(cx, yB - c - 2 * lift, cx - ext, yB + c);
    ctx.closePath();
    ctx.fill();
    // Closed (asleep, or mid-blink): a soft lash line so the eye reads as shut,
    // not as a screen that went off; asleep it breathes: it lifts a little and
    // brightens with each breath in.
    const shut = clamp(((top + bottom) / 100 - 0.9) / 0.1, 0, 1);
    if (shut > 0) {
      const inhale = (P.breathe / 100) * (1 - exhale(s));
      const y = cy - R * LASH_LIFT * inhale;
      ctx.globalAlpha = shut * (1 - 0.5 * (P.breathe / 100) * exhale(s));
      ctx.beginPath();
      ctx.moveTo(cx - R * 0.85, y);
      ctx.quadraticCurveTo(cx, y + R * (0.28 - LASH_LIFT * inhale), cx + R * 0.85, y);
      ctx.lineWidth = Math.max(2, R * 0.06);
      ctx.lineCap = "round";
      ctx.strokeStyle = LASH;
      ctx.stroke();
      ctx.globalAlpha = 1;
    }
  }

  // --- the frame ---------------------------------------------------------------------

  // `s`: {which, style, pose, lids, calm, blink, yawN, pitchN, verg, dilation,
  // spinAngle, t}; draws the whole canvas.
  function draw(ctx, W, H, s) {
    ctx.fillStyle = s.style.background;
    ctx.fillRect(0, 0, W, H);
    // Facing the viewer: the robot's right eye is on the viewer's left.
    const cells = s.which === "both"
      ? [["right", layout(s, "right", 0, 0, W / 2, H)], ["left", layout(s, "left", W / 2, 0, W / 2, H)]]
      : [[s.which, layout(s, s.which, 0, 0, W, H)]];
    if (s.style.kind === "glow") drawGlow(ctx, s, cells, W, H);
    else for (const [side, L] of cells) eyeballEye(ctx, s, side, L);
    if (s.calm > 0.001) {        // the connecting face is dimmed toward the background
      ctx.globalAlpha = REST_DIM * s.calm;
      ctx.fillStyle = s.style.background;
      ctx.fillRect(0, 0, W, H);
      ctx.globalAlpha = 1;
    }
  }

  return { draw, lidsOf };
})();
