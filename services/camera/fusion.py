"""Distance cue fusion, pure: several pinhole distances -> one, with a record.

Every distance cue is `Z = fx * S / s` for a real size S (face width,
inter-pupillary distance, iris diameter) seen `s` pixels wide, wrong by
the spread of S between people and by pixel noise relative to `s`. So a
cue's relative variance is `prior² + (px_sd / s)² (+ extra²)`, and the
cues are averaged on log Z with inverse-variance weights: the iris
dominates close up and vanishes far away, without a hard switch. A cue
below its `min_px` is not used; with three or more cues, an outlier is
dropped. `Fusion.cues` records which cues were used with which weight;
`IrisCalibration` gives the held iris cue (`iris_held`) between iris
measurements.

Rationale: docs/camera.md, 'Cue fusion in detail'.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

WIDTH = "width"
EYES = "eyes"
IRIS = "iris"
IRIS_HELD = "iris_held"

USED = "used"
TOO_SMALL = "too small"
OUTLIER = "outlier"
INVALID = "invalid"

# Relative spreads of the real sizes between adults (why each: module docstring).
WIDTH_PRIOR_SD = 0.08
EYES_PRIOR_SD = 3.5 / 63.0
IRIS_PRIOR_SD = 0.5 / 11.7

# Pixel noise of each measurement (px, one sigma). The box edges move by a
# couple of pixels frame to frame; each eye keypoint by about a pixel, so
# their distance by ~1.5. The iris diameter stayed within 0.3 px of the
# expected one on the tuning photo from 23 px down to 4.5 px; 0.7 px allows
# for real cameras (noise, compression, focus), which the photo does not have.
WIDTH_PX_SD = 2.0
EYES_PX_SD = 1.5
IRIS_PX_SD = 0.7

IRIS_MIN_PX = 6.0
"""Below this the iris cue is ignored: at 6 px its pixel error alone is ~12%,
and the model's diameter starts to shrink with blur (4% small at 4.5 px on the
tuning photo; 10-13% at 4-5 px on the held-out one, which was seen before this
value was set), a bias the weights cannot describe."""
EYES_MIN_PX = 4.0
"""Keypoints closer than this are one blob; the eye cue is meaningless."""
EYES_MAX_YAW = math.radians(70)
"""The yaw correction divides by cos(yaw); beyond this it divides by noise."""


@dataclass(frozen=True)
class Cue:
    """One distance cue: its distance, how big its measure is, and its error model."""

    name: str
    z_m: float
    size_px: float
    prior_sd: float
    px_sd: float
    min_px: float = 0.0
    extra_sd: float = 0.0
    """Further relative error (the eye cue's yaw correction)."""

    @property
    def rel_var(self) -> float:
        """Relative variance of `z_m` (the square of its relative standard error)."""
        px = self.px_sd / self.size_px if self.size_px > 0 else math.inf
        return self.prior_sd ** 2 + px ** 2 + self.extra_sd ** 2

    @property
    def usable(self) -> str:
        """USED if the cue can be used at all, else why not."""
        if not (math.isfinite(self.z_m) and self.z_m > 0 and math.isfinite(self.size_px)):
            return INVALID
        if self.size_px < max(self.min_px, 1e-9):
            return TOO_SMALL
        return USED


def width_cue(fx: float, face_width_m: float, box_px: float) -> Cue:
    """The pinhole width cue: a face box `box_px` wide covers `face_width_m` metres."""
    z = fx * face_width_m / box_px if box_px > 0 else math.nan
    return Cue(WIDTH, z, box_px, WIDTH_PRIOR_SD, WIDTH_PX_SD)


def eye_cue(fx: float, eye_distance_m: float, eye_px: float, yaw_rad: float = 0.0) -> Cue:
    """Eye keypoints `eye_px` apart (as seen), corrected for head yaw by 1/cos(yaw).

    The correction's own error grows with the yaw (a 10 degree yaw error at
    60 degrees is a 30% change of 1/cos), so it is added as `extra_sd`;
    beyond 70 degrees the cue is not used.
    """
    corrected = yaw_corrected(eye_px, yaw_rad)
    z = fx * eye_distance_m / corrected if corrected > 0 else math.nan
    return Cue(EYES, z, eye_px, EYES_PRIOR_SD, EYES_PX_SD, EYES_MIN_PX, yaw_sd(yaw_rad))


def yaw_corrected(eye_px: float, yaw_rad: float) -> float:
    """Eye keypoint distance as if facing the camera (NaN beyond `EYES_MAX_YAW`)."""
    if abs(yaw_rad) > EYES_MAX_YAW:
        return math.nan
    return eye_px / math.cos(yaw_rad)


def yaw_sd(yaw_rad: float) -> float:
    """Relative error the yaw correction adds: d(1/cos)/(1/cos) = tan(yaw) dyaw,
    with the yaw known to ~0.1 rad (keypoint model of the head)."""
    return 0.1 * abs(math.tan(min(abs(yaw_rad), EYES_MAX_YAW)))


def iris_cue(fx: float, iris_px: float, iris_m: float = 0.0117,
             min_px: float = IRIS_MIN_PX) -> Cue:
    """An iris `iris_px` across (horizontal diameter, mean of both eyes)."""
    z = fx * iris_m / iris_px if iris_px > 0 else math.nan
    return Cue(IRIS, z, iris_px, IRIS_PRIOR_SD, IRIS_PX_SD, min_px)


@dataclass(frozen=True)
class Weighted:
    """A cue as the fusion treated it: its weight (0 when not used) and why."""

    name: str
    z_m: float
    size_px: float
    rel_sd: float
    weight: float
    status: str


@dataclass(frozen=True)
class Fusion:
    """The fused distance, its relative standard error, and every cue's part in it."""

    z_m: float
    rel_sd: float
    cues: tuple[Weighted, ...]

    @property
    def used(self) -> tuple[str, ...]:
        """Names of the cues that got a weight, heaviest first."""
        return tuple(c.name for c in sorted(self.cues, key=lambda c: -c.weight)
                     if c.status == USED)

    def weight(self, name: str) -> float:
        """The weight of cue `name` (0 when absent or not used)."""
        return sum(c.weight for c in self.cues if c.name == name)

    def summary(self) -> str:
        """One short line for the debug image, e.g. `0.52 m iris 71% eyes 19% width 10%`."""
        parts = [f"{c.name} {round(100 * c.weight)}%" for c in
                 sorted(self.cues, key=lambda c: -c.weight) if c.status == USED]
        return f"{self.z_m:.2f} m " + " ".join(parts)

    def as_dict(self) -> dict[str, object]:
        """Flat values for the diagnostics message (`dist_<cue>_m`, `dist_<cue>_w`)."""
        out: dict[str, object] = {"dist_m": round(self.z_m, 3),
                                  "dist_rel_sd": round(self.rel_sd, 3)}
        for c in self.cues:
            if math.isfinite(c.z_m):
                out[f"dist_{c.name}_m"] = round(c.z_m, 3)
            out[f"dist_{c.name}_w"] = round(c.weight, 3) if c.status == USED else c.status
        return out


def _combine(cues: Sequence[Cue]) -> tuple[float, float, list[float]]:
    """Inverse-variance mean of log Z: (Z, relative sd, normalised weights)."""
    inv = [1.0 / c.rel_var for c in cues]
    total = sum(inv)
    weights = [w / total for w in inv]
    log_z = sum(w * math.log(c.z_m) for w, c in zip(weights, cues, strict=True))
    return math.exp(log_z), math.sqrt(1.0 / total), weights


def fuse(cues: Sequence[Cue], outlier_sigmas: float = 3.0) -> Fusion | None:
    """One distance from `cues`; None when none of them can be used.

    Unusable cues (too small, invalid) are kept in the record with weight 0.
    With three or more usable cues, the one furthest from the others (in
    units of the combined spread) is dropped if beyond `outlier_sigmas`.
    """
    status = {id(c): c.usable for c in cues}
    usable = [c for c in cues if status[id(c)] == USED]
    if not usable:
        return None
    if len(usable) >= 3:
        worst, worst_score = None, outlier_sigmas
        for c in usable:
            others = [o for o in usable if o is not c]
            z_o, sd_o, _ = _combine(others)
            score = abs(math.log(c.z_m / z_o)) / math.sqrt(c.rel_var + sd_o ** 2)
            if score > worst_score:
                worst, worst_score = c, score
        if worst is not None:
            status[id(worst)] = OUTLIER
            usable = [c for c in usable if c is not worst]
    z, sd, weights = _combine(usable)
    weight_of = {id(c): w for c, w in zip(usable, weights, strict=True)}
    record = tuple(
        Weighted(c.name, c.z_m, c.size_px, math.sqrt(c.rel_var) if c.size_px > 0 else math.inf,
                 weight_of.get(id(c), 0.0), status[id(c)])
        for c in cues
    )
    return Fusion(z, sd, record)


CALIBRATION_FLOOR_SD = 0.02
"""The held ratio never claims to be better than 2%: successive measurements of
one person share the model's bias for that face, so averaging more of them
does not make it vanish as 1/sqrt(n) would say."""
IPD_RANGE_M = (0.050, 0.078)
"""Adult inter-pupillary distances (mean 63 mm, sd 3.5 mm: about ±4 sd). An
iris measurement implying a person outside this is a failed measurement."""


class IrisCalibration:
    """The followed person's iris size relative to their eye keypoints, held
    between iris measurements (the iris stage is too slow for every frame).

    An iris measurement close up gives the ratio `iris_px / eye_px` of this
    person, which does not change with distance: in effect it measures their
    inter-pupillary distance (`0.0117 m / ratio`) instead of assuming the
    population's 63 mm. Every later frame then gets an `iris_held` cue from
    the current eye keypoints alone, `Z = fx * 0.0117 / (ratio * eye_px)`,
    which keeps the iris's accuracy at distances where the iris itself is
    too small to measure, for no inference at all. The pixel noise of
    `eye_px` is shared with the eye cue, so the fused `rel_sd` is somewhat
    optimistic when both are used; the weights are still right in order.

    Call `reset()` when the followed person changes.
    """

    def __init__(self, iris_m: float = 0.0117, outlier_sigmas: float = 3.0) -> None:
        self.iris_m = iris_m
        self.outlier_sigmas = outlier_sigmas
        self.log_ratio: float | None = None
        self.var = math.inf
        self.measurements = 0
        self.rejected = 0

    def reset(self) -> None:
        """Forget the person (a new one is followed)."""
        self.log_ratio, self.var, self.measurements = None, math.inf, 0

    def update(self, iris_px: float, eye_px: float, yaw_rad: float = 0.0,
               min_iris_px: float = IRIS_MIN_PX) -> bool:
        """Add one measurement: the iris diameter and the eye keypoint distance (as
        seen, with the head's yaw) of the same frame. Returns whether it was accepted.

        Only frontal-ish frames calibrate (|yaw| < 30 degrees): the yaw correction's
        error would otherwise become part of the person's ratio for good.
        """
        eye = yaw_corrected(eye_px, yaw_rad)
        if (iris_px < min_iris_px or eye_px < EYES_MIN_PX or not math.isfinite(eye)
                or abs(yaw_rad) > math.radians(30)):
            return False
        ratio = iris_px / eye
        ipd_m = self.iris_m / ratio
        if not IPD_RANGE_M[0] <= ipd_m <= IPD_RANGE_M[1]:
            self.rejected += 1
            return False
        var = (IRIS_PX_SD / iris_px) ** 2 + (EYES_PX_SD / eye_px) ** 2 + yaw_sd(yaw_rad) ** 2
        log_r = math.log(ratio)
        if self.log_ratio is None:
            self.log_ratio, self.var = log_r, max(var, CALIBRATION_FLOOR_SD ** 2)
        else:
            if abs(log_r - self.log_ratio) > self.outlier_sigmas * math.sqrt(var + self.var):
                self.rejected += 1
                return False
            total = 1.0 / self.var + 1.0 / var
            self.log_ratio = (self.log_ratio / self.var + log_r / var) / total
            self.var = max(1.0 / total, CALIBRATION_FLOOR_SD ** 2)
        self.measurements += 1
        return True

    @property
    def ipd_m(self) -> float | None:
        """This person's inter-pupillary distance as the iris says, or None before any."""
        return None if self.log_ratio is None else self.iris_m / math.exp(self.log_ratio)

    def cue(self, fx: float, eye_px: float, yaw_rad: float = 0.0) -> Cue | None:
        """The held iris cue for this frame's eye keypoint distance (as seen) and yaw;
        None before the first accepted measurement."""
        if self.log_ratio is None:
            return None
        iris_px = math.exp(self.log_ratio) * yaw_corrected(eye_px, yaw_rad)
        z = fx * self.iris_m / iris_px if iris_px > 0 else math.nan
        # Error: the iris prior, the held ratio's, this frame's keypoints and yaw.
        extra = math.sqrt(self.var + yaw_sd(yaw_rad) ** 2)
        return Cue(IRIS_HELD, z, eye_px, IRIS_PRIOR_SD, EYES_PX_SD, EYES_MIN_PX, extra)
