// BuddyBot eyes: drawing one frame of the face from the eased state.
//
// Two kinds of style (services/eyes/styles.py): "glow", a rounded glowing
// shape per eye that moves as a whole and whose lids cut it (a closed eye
// is a thin glowing line), and "eyeball", a white ball whose iris moves and
// whose lids are background-coloured caps. Both read the same pose numbers.
//
// Shared "alive" cues (eyes.js eases their inputs):
// * lids follow the gaze up and down (looking up raises the top lid);
// * vergence: each eye moves toward the nose as the person comes closer;
// * curiosity: the eye on the side looked at grows, the other shrinks a bit;
// * squash and stretch: a blinking glow eye gets flatter and wider.
//
// The glow is cheap on purpose: the shapes are drawn again on a canvas a
// quarter of the size, blurred there (shadowBlur on ~1/16 of the pixels)
// and added onto the frame scaled up, instead of blurring the full frame.
"use strict";

window.EyeDraw = (() => {
  const REST_LIDS = { top: 30, bottom: 16 };   // the connecting face: half closed
  const REST_DIM = 0.55;                       // ... and dimmed toward the background
  const SCLERA = "#f2f4f8";
  const PUPIL = "#000000";
  const LASH = "#3c4966";                      // lash line of a closed eyeball
  const GLOW_SCALE = 0.125;                    // the glow layer's size, of the canvas
  const GLOW_BLUR = 0.12;                      // halo blur, of the eye's cell
  const GLOW_GAIN = 1.6;                       // halo strength at glow 100
  const BREATH_HZ = 0.25;                      // asleep: one slow breath every 4 s
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
    // The commanded lids (eyes/lids), at least what the pose asks for.
    let top = Math.max(L.top, P.top_lid) * (1 - uncut);
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

  function breath(s) {
    const wave = 0.5 - 0.5 * Math.cos(2 * Math.PI * BREATH_HZ * s.t / 1000);
    return 1 - (s.pose.breathe / 100) * wave;
  }

  // --- shapes (paths only) -----------------------------------------------------------

  function roundRect(c, x, y, w, h, r) {
    r = clamp(r, 0, Math.min(w, h) / 2);
    c.moveTo(x + r, y);
    c.arcTo(x + w, y, x + w, y + h, r);
    c.arcTo(x + w, y + h, x, y + h, r);
    c.arcTo(x, y + h, x, y, r);
    c.arcTo(x, y, x + w, y, r);
    c.closePath();
  }

  // A heart filling the unit box -0.5..0.5 (scaled by the caller's transform).
  function heartPath(c) {
    c.moveTo(0, 0.46);
    c.bezierCurveTo(-0.3, 0.24, -0.52, 0.02, -0.5, -0.2);
    c.bezierCurveTo(-0.48, -0.44, -0.14, -0.52, 0, -0.26);
    c.bezierCurveTo(0.14, -0.52, 0.48, -0.44, 0.5, -0.2);
    c.bezierCurveTo(0.52, 0.02, 0.3, 0.24, 0, 0.46);
    c.closePath();
  }

  // A five-pointed star with rounded-off tips, in the unit box.
  function starPath(c, angle) {
    const outer = 0.5;
    const inner = 0.22;
    for (let i = 0; i < 10; i++) {
      const r = i % 2 === 0 ? outer : inner;
      const a = angle - Math.PI / 2 + (i * Math.PI) / 5;
      if (i === 0) c.moveTo(r * Math.cos(a), r * Math.sin(a));
      else c.lineTo(r * Math.cos(a), r * Math.sin(a));
    }
    c.closePath();
  }

  function fillUnit(c, cx, cy, sx, sy, path) {
    c.save();
    c.translate(cx, cy);
    c.scale(sx, sy);
    c.beginPath();
    path(c);
    c.fill();
    c.restore();
  }

  // --- glow --------------------------------------------------------------------------

  // One glow eye on context `c`: the shape, cut by the lids.
  function glowEye(c, s, side, L, fill) {
    const P = s.pose;
    const st = s.style;
    const lids = lidsOf(s, side, clamp(P.heart + P.star, 0, 1));
    const squash = s.blink * (st.squash / 100);
    const ew = (L.S * P.width / 100) * L.grow * (1 + s.blink * (st.stretch / 100));
    const line = CLOSED_LINE * L.S;
    const eh = Math.max(line, (L.S * P.height / 100) * L.grow * (1 - squash));
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
    const plain = clamp(1 - P.heart - P.star, 0, 1);
    if (plain > 0.01) {
      c.globalAlpha = plain;
      c.beginPath();
      roundRect(c, cx - ew / 2, cy - eh / 2, ew, eh, (P.roundness / 100) * Math.min(ew, eh) / 2);
      c.fill();
    }
    const beat = 1 + (P.beat / 100) * Math.max(0, Math.sin(s.t / 1000 * 2 * Math.PI * 1.2)) ** 4;
    if (P.heart > 0.01) {
      c.globalAlpha = P.heart;
      fillUnit(c, cx, cy, ew * beat, eh * beat, heartPath);
    }
    if (P.star > 0.01) {
      c.globalAlpha = P.star;
      fillUnit(c, cx, cy, ew, eh, (cc) => starPath(cc, s.spinAngle));
    }
    c.restore();
  }

  function drawGlow(ctx, s, cells, W, H) {
    const P = s.pose;
    const k = (P.brightness / 100) * breath(s);
    const fill = colourOf(P, k);
    const shaded = [colourOf({ r: lighten(P.r), g: lighten(P.g), b: lighten(P.b) }, k),
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
      for (const [side, L] of cells) glowEye(nearCtx, s, side, L, fill);
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
    for (const [side, L] of cells) glowEye(ctx, s, side, L, shaded);
  }

  // Half-sizes (px) of the box an eye's halo can reach from its centre.
  function glowReach(s, L) {
    const P = s.pose;
    const big = 1.1 * L.grow * (1 + s.style.stretch / 100) * (1 + P.beat / 100);
    const margin = 2.5 * GLOW_BLUR * L.S;
    return { x: (L.S * P.width / 200) * big + margin, y: (L.S * P.height / 200) * big + margin };
  }

  function lighten(v) { return v + (255 - v) * 0.2; }

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
    const plain = clamp(1 - P.heart - P.star, 0, 1);
    if (plain > 0.01 && irisR > 0) {
      ctx.globalAlpha = plain;
      ctx.beginPath();
      ctx.arc(gx, gy, irisR, 0, 2 * Math.PI);
      ctx.fillStyle = colourOf(P, 1);
      ctx.fill();
      ctx.lineWidth = irisR * 0.08;
      ctx.strokeStyle = "rgba(0,0,0,0.25)";
      ctx.stroke();
      // Dilation is a percentage of the iris, kept within 12..92 % so the
      // pupil never vanishes and a ring of iris always shows.
      const pupilR = irisR * clamp((s.dilation / 100) * (P.pupil / 100), 0.12, 0.92);
      ctx.beginPath();
      ctx.arc(gx, gy, pupilR, 0, 2 * Math.PI);
      ctx.fillStyle = PUPIL;
      ctx.fill();
      ctx.globalAlpha = 1;
    }
    ctx.fillStyle = colourOf(P, 1);
    const size = Math.max(irisR, R * 0.46) * 2.3;
    if (P.heart > 0.01) {
      ctx.globalAlpha = P.heart;
      const beat = 1 + (P.beat / 100) * Math.sin(s.t / 1000 * 2 * Math.PI * 1.3);
      fillUnit(ctx, gx, gy, size * beat, size * beat, heartPath);
    }
    if (P.star > 0.01) {
      ctx.globalAlpha = P.star;
      fillUnit(ctx, gx, gy, size, size, (c) => starPath(c, s.spinAngle));
    }
    ctx.globalAlpha = 1;
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
    // not as a screen that went off; asleep it breathes.
    const shut = clamp(((top + bottom) / 100 - 0.9) / 0.1, 0, 1);
    if (shut > 0) {
      ctx.globalAlpha = shut * breath(s);
      ctx.beginPath();
      ctx.moveTo(cx - R * 0.85, cy);
      ctx.quadraticCurveTo(cx, cy + R * 0.28, cx + R * 0.85, cy);
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
