// BuddyBot eyes: key poses and their interpolation (no drawing, no I/O).
//
// A style (services/eyes/styles.py, sent in the hello) gives every expression
// a pose: a few numbers (size, roundness, lids, glow, ...), a colour and a
// shape. The page never jumps from one pose to the next: on a change it
// eases every number from where it is to the new pose (ease in and out over
// the style's transition_ms), the colour channel by channel, and the shape
// as weights (a heart grows in while the plain eye shrinks away). The
// commanded lids (eyes/lids, which come with every expression) are part of
// the pose, so they close and open with it, not on a clock of their own; a
// pose may take its own time (falling asleep is slow).
"use strict";

window.EyePose = (() => {
  // ExpressionAction order (contract/messages.py), as the style's poses name them.
  const NAMES = ["AWAKE", "SLEEP", "SLEEPY", "GRIN", "SAD", "LOOK_RANDOM", "LOVE", "STAR",
    "ALERT"];
  const NUM = ["width", "height", "roundness", "top_lid", "top_lid_angle", "bottom_lid",
    "bottom_lid_curve", "iris", "pupil", "glow", "brightness", "breathe", "sway", "beat", "spin"];
  const STYLE_NUM = ["lid_follow", "curiosity", "vergence", "squash", "stretch", "reach",
    "transition_ms"];

  // Until the first hello (the renderer sends its style at once, so this shows
  // only while it cannot be reached): a plain glow eye for every expression.
  const BASE = {
    width: 50, height: 56, roundness: 45, top_lid: 0, top_lid_angle: 0, bottom_lid: 0,
    bottom_lid_curve: 0, iris: 70, pupil: 100, glow: 70, brightness: 100, breathe: 0, sway: 0,
    beat: 0, spin: 0, color: "", shape: "eye", transition_ms: 0,
  };
  const FALLBACK = {
    name: "fallback", kind: "glow", description: "", background: "#03050a", color: "#3ce6ff",
    lid_follow: 14, curiosity: 12, vergence: 7, squash: 100, stretch: 14, reach: 15,
    transition_ms: 280, poses: Object.fromEntries(NAMES.map((n) => [n, BASE])),
  };

  function isNum(v) { return typeof v === "number" && Number.isFinite(v); }
  function isColour(v) { return typeof v === "string" && /^#[0-9a-fA-F]{6}$/.test(v); }

  // A style from the server, checked before use (a bad one is refused whole).
  function isStyle(st) {
    if (!st || typeof st !== "object" || !["glow", "eyeball"].includes(st.kind)) return false;
    if (!isColour(st.background) || !isColour(st.color)) return false;
    if (!STYLE_NUM.every((k) => isNum(st[k]))) return false;
    if (!st.poses || typeof st.poses !== "object") return false;
    return NAMES.every((n) => {
      const p = st.poses[n];
      return p && typeof p === "object" && NUM.every((k) => isNum(p[k]))
        && isNum(p.transition_ms) && p.transition_ms >= 0
        && (p.color === "" || isColour(p.color)) && ["eye", "heart", "star"].includes(p.shape);
    });
  }

  function rgb(hex) {
    const v = parseInt(hex.slice(1), 16);
    return [(v >> 16) & 255, (v >> 8) & 255, v & 255];
  }

  // The flat pose the page eases toward: numbers, r/g/b, shape weights and the
  // commanded lids ({left: {top, bottom}, right: ...}, % closed; none: open).
  // An empty pose colour is the style's (eyeball: the iris_color setting).
  function target(style, expression, irisColour, lids) {
    const p = poseOf(style, expression);
    const out = {};
    for (const k of NUM) out[k] = p[k];
    const L = lids || { left: { top: 0, bottom: 0 }, right: { top: 0, bottom: 0 } };
    [out.lid_lt, out.lid_lb, out.lid_rt, out.lid_rb] = [L.left.top, L.left.bottom, L.right.top,
      L.right.bottom];
    const colour = p.color || (style.kind === "eyeball" ? irisColour : style.color);
    [out.r, out.g, out.b] = rgb(isColour(colour) ? colour : style.color);
    out.heart = p.shape === "heart" ? 1 : 0;
    out.star = p.shape === "star" ? 1 : 0;
    return out;
  }

  function poseOf(style, expression) { return style.poses[NAMES[expression]] || style.poses.AWAKE; }

  // How long the change into `expression`'s pose takes, ms: its own time, else the style's.
  function duration(style, expression) {
    return poseOf(style, expression).transition_ms || style.transition_ms;
  }

  // Colours ease through hue (the short way round), not through RGB, which
  // would pass through grey between, say, cyan and pink.
  function lerp(a, b, k) {
    const out = {};
    for (const key of Object.keys(b)) out[key] = a[key] + (b[key] - a[key]) * k;
    const from = hsl(a.r, a.g, a.b);
    const to = hsl(b.r, b.g, b.b);
    if (from[1] < 0.05) from[0] = to[0];     // a grey has no hue of its own
    if (to[1] < 0.05) to[0] = from[0];
    const turn = ((to[0] - from[0] + 540) % 360) - 180;
    [out.r, out.g, out.b] = rgbOf((from[0] + turn * k + 360) % 360,
      from[1] + (to[1] - from[1]) * k, from[2] + (to[2] - from[2]) * k);
    return out;
  }

  function hsl(r, g, b) {
    r /= 255; g /= 255; b /= 255;
    const max = Math.max(r, g, b);
    const min = Math.min(r, g, b);
    const l = (max + min) / 2;
    const d = max - min;
    if (d < 1e-6) return [0, 0, l];
    const s = d / (1 - Math.abs(2 * l - 1));
    let h = max === r ? ((g - b) / d) % 6 : max === g ? (b - r) / d + 2 : (r - g) / d + 4;
    h *= 60;
    return [h < 0 ? h + 360 : h, s, l];
  }

  function rgbOf(h, s, l) {
    const c = (1 - Math.abs(2 * l - 1)) * s;
    const x = c * (1 - Math.abs(((h / 60) % 2) - 1));
    const m = l - c / 2;
    const [r, g, b] = h < 60 ? [c, x, 0] : h < 120 ? [x, c, 0] : h < 180 ? [0, c, x]
      : h < 240 ? [0, x, c] : h < 300 ? [x, 0, c] : [c, 0, x];
    return [(r + m) * 255, (g + m) * 255, (b + m) * 255];
  }

  // Slow in, slow out (cubic): a pose change starts and lands softly.
  function ease(k) { return k < 0.5 ? 4 * k * k * k : 1 - Math.pow(-2 * k + 2, 3) / 2; }

  return { NAMES, NUM, FALLBACK, isStyle, target, duration, lerp, ease, rgb };
})();
