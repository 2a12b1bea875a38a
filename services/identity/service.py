"""`buddybot run identity`: who the followed face is, per track, with consent.

Reads `camera/<cam>/image` (kept in a small ring by stamp, never decoded
unless used) and `camera/<cam>/faces` (the detector's boxes with their
keypoints, stamped like the frame they came from). The followed face's
boxes make tracks (`tracks.py`); each track embeds one frame in a few, one
at a time, on this process's embedding thread, and votes (`vote.py`); the
name goes out on `identity/<cam>/name` (latched) when it changes. The face
detector never waits for any of this: it is another process.

Consent: `identity/enrol` takes the one face in front of the camera now,
`identity/forget` erases one person or everybody (a followed face carrying
a forgotten name turns unknown in the same step), `identity/list` names
who is enrolled. The gallery stores embeddings, never images; logs never
hold an embedding. A gallery file that cannot be trusted, or a missing
model, leaves the service running with no names and an ERROR status.

Threads: faces on a worker (FIFO), images inline (a ring append),
embeddings on their own thread, queries on the node's workers, the timer
on the node's timer thread; one lock guards tracks, vote, gallery and the
name publisher. Details: docs/identity.md, 'The service'.
"""

from __future__ import annotations

import argparse
import logging
import os
import queue
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from buddybot.contract import images, keys
from buddybot.contract import messages as m
from buddybot.identity import embedding, gallery
from buddybot.identity.frames import ImageRing
from buddybot.identity.matching import Index
from buddybot.identity.settings import GALLERY_FILE, IdentitySettings
from buddybot.identity.tracks import FaceTracks
from buddybot.identity.vote import Answer, TrackVote, VoteRules
from buddybot.runtime.config import resolve_path
from buddybot.runtime.errors import ConfigError
from buddybot.runtime.node import Node
from buddybot.runtime.overrides import given, merge, settings_option
from buddybot.runtime.params import LiveSettings
from buddybot.runtime.private_files import is_operator, state_dir
from buddybot.runtime.service import ServiceContext

log = logging.getLogger("buddybot.identity")
NOT_OPERATOR = ("enrolling and forgetting faces is an operator's act: the robot's operator "
                "secret is needed (`buddybot secret show` prints it)")

RETENTION_PERIOD_S = 3600.0
"""How often the retention limit is applied (and once at start)."""
EMBED_NICE = 10
"""Nice value of the embedding thread: a name may come a frame later, the gaze may not."""
TICK_S = 0.25
"""The timer: a lost face's track ends within this of `lost_s`."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options override their `[identity]` keys (default: settings.py)."""
    settings_option(parser, "--camera", struct=IdentitySettings, field="camera", metavar="NAME")
    settings_option(parser, "--gallery", struct=IdentitySettings, field="gallery",
                    metavar="FILE")


def settings_from(ctx: ServiceContext) -> IdentitySettings:
    """`[identity]` with the command line on top, the camera name checked."""
    settings = merge(ctx.config.section(IdentitySettings), ctx.args)
    if not keys.valid_robot_id(settings.camera):
        raise ConfigError(f"[identity] camera: invalid camera name {settings.camera!r}")
    return settings


def gallery_path(ctx: ServiceContext, settings: IdentitySettings) -> Path:
    """The gallery file: `gallery` (relative to the config file, or to the working
    directory when given as --gallery), else the state directory's."""
    if not settings.gallery:
        return state_dir() / GALLERY_FILE
    return resolve_path(ctx.config, settings.gallery,
                        from_command_line=given(ctx.args, IdentitySettings, "gallery"))


def rules_of(s: IdentitySettings) -> VoteRules:
    """The vote's rules; `votes_needed` beyond `vote_window` counts as all of the window."""
    return VoteRules(every_nth=s.every_nth, needed=min(s.votes_needed, s.vote_window),
                     window=s.vote_window, recheck_s=s.recheck_s)


def followed_box(msg: m.FaceDetections) -> m.FaceBox | None:
    return next((f for f in msg.faces if f.followed), None)


def keypoints_of(face: m.FaceBox) -> list[tuple[float, float]]:
    return [(p.x, p.y) for p in face.keypoints]


@dataclass(frozen=True)
class Job:
    """One embedding to compute: the followed face of one frame of one track."""

    track: int
    stamp_ns: int
    image: m.Image
    keypoints: list[tuple[float, float]]


@dataclass
class Enrolment:
    """Frames with exactly one face, collected for one enrol request."""

    samples: int
    frames: list[tuple[m.Image, list[tuple[float, float]]]] = field(default_factory=list)
    no_face: int = 0
    many_faces: int = 0
    done: threading.Event = field(default_factory=threading.Event)

    def offer(self, msg: m.FaceDetections, image: m.Image | None) -> None:
        if not msg.faces:
            self.no_face += 1
        elif len(msg.faces) > 1:
            self.many_faces += 1
        elif image is not None and len(msg.faces[0].keypoints) >= len(embedding.TEMPLATE):
            self.frames.append((image, keypoints_of(msg.faces[0])))
        if len(self.frames) >= self.samples:
            self.done.set()

    def shortfall(self, timeout_s: float) -> str:
        """Why too few frames were collected, for the refusal."""
        got = (f"{len(self.frames)} of {self.samples} frames with exactly one face in "
               f"{timeout_s:g} s")
        if self.many_faces >= max(self.no_face, 1):
            return (f"more than one face in view ({self.many_faces} frames): only the person "
                    f"enrolling may face the camera ({got})")
        if self.no_face or not self.frames:
            return f"no face in view: face the camera, closer or in better light ({got})"
        return f"not enough frames ({got})"


class IdentityService:
    """Wires one Node to the tracks, the vote, the gallery and the embedder."""

    def __init__(self, node: Node, settings: IdentitySettings, path: Path,
                 embedder: embedding.Embedder | None, model_problem: str | None) -> None:
        self.node = node
        self.s = settings
        self.path = path
        self.embedder = embedder
        self.model_problem = model_problem
        self.rules = rules_of(settings)
        self.images = ImageRing()
        self.tracks = FaceTracks(settings.min_iou, settings.lost_s)
        self.vote: TrackVote | None = None
        self.gallery: gallery.Gallery | None = None
        self.gallery_problem: str | None = None
        self._last_forget_ns = 0
        """When someone was last forgotten (wall ns): every enrolment asked before loses."""
        self.key_path = gallery.key_path()
        self.key: bytes | None = None
        """The gallery key (None until read, or when its file is unusable)."""
        self.index = Index.build([], np.zeros((0, embedding.DIM), np.float32))
        self.enrolment: Enrolment | None = None
        self.inflight: Job | None = None
        """The frame being embedded for a track (one at a time, whatever the track)."""
        self._net_lock = threading.Lock()
        """dlib's network is used by the embedding thread and by enrolments."""
        self._lock = threading.Lock()
        self._jobs: queue.Queue[Job | None] = queue.Queue(maxsize=2)
        self._name_pub = node.publisher(keys.FACE_NAME, camera=settings.camera)
        self._published: tuple[int | None, str | None] | None = None
        self._frame_id = settings.camera
        self._faces_ns = 0
        self._seen_dirty = False
        self._seen_saved = time.monotonic()
        self._retention_due = 0.0
        self._thread = threading.Thread(target=self._embed_loop, name="identity-embed",
                                        daemon=True)

    # -- start, settings, status --

    def apply_settings(self, settings: IdentitySettings) -> None:
        """A live change: thresholds, vote and tracking rules apply from the next frame."""
        with self._lock:
            self.s = settings
            self.rules = rules_of(settings)
            if self.vote is not None:
                self.vote.rules = self.rules
            self.tracks.min_iou, self.tracks.lost_s = settings.min_iou, settings.lost_s

    def prepare(self) -> None:
        """Load the gallery, apply the retention limit, publish "no face" (latched)."""
        with self._lock:
            self._load_gallery()
            self._expire(time.time())
            self._publish(m.now_ns())

    def start(self) -> None:
        self.prepare()
        self._thread.start()
        self.node.subscribe(keys.CAMERA_IMAGE, self._on_image, camera=self.s.camera)
        self.node.subscribe(keys.FACES, self._on_faces, delivery="queue", queue_size=8,
                            camera=self.s.camera)
        self.node.serve(keys.IDENTITY_ENROL, self.enrol)
        self.node.serve(keys.IDENTITY_FORGET, self.forget)
        self.node.serve(keys.IDENTITY_LIST, self.list_people)
        self.node.every(TICK_S, self.tick, name="identity-tick")

    def close(self) -> None:
        """Stop the embedding thread and save last-seen times not saved yet (the node's
        handles close with the node)."""
        self._jobs.put(None)  # never blocks: at most one job waits (maxsize 2)
        with self._lock:
            if self._seen_dirty:
                self._seen_dirty = False
                self._save("last-seen times")

    def _load_gallery(self) -> None:
        """Read the gallery file; on any problem: no names, and say why. Under the lock."""
        try:
            self.key, made = gallery.load_key(self.key_path)
            self.gallery = gallery.load(self.path, embedding.MODEL_ID, self.key, unkeyed=made)
            self.gallery_problem = None
            if made and self.gallery.people:  # the old format, read once: signed from now on
                log.info("gallery key made (%s); the gallery is signed with it", self.key_path)
                self._save("signed with the new key")
        except gallery.GalleryError as exc:
            self.gallery, self.gallery_problem = None, str(exc)
            log.error("gallery unusable, running without names: %s", exc)
        self._rebuild()

    def _rebuild(self) -> None:
        """The match index from the gallery, and the status. Under the lock."""
        if self.gallery is None:
            self.index = Index.build([], np.zeros((0, embedding.DIM), np.float32))
        else:
            self.index = Index.build(*self.gallery.table())
        self.node.diagnostics.values["people"] = len(self.index.people)
        if self.gallery_problem is not None:
            self.node.diagnostics.set(
                "ERROR", f"gallery unusable, no names: {self.gallery_problem} (enrol and "
                "forget will not overwrite it; `people forget --all` replaces it, or move it)")
        elif self.model_problem is not None:
            # The install command first: a long model path must not clip it away.
            self.node.diagnostics.set(
                "ERROR", f"no face model (pip install -e '.[identity]'), no names: "
                f"{self.model_problem}")
        else:
            self.node.diagnostics.set("OK", f"{len(self.index.people)} people enrolled")

    # -- frames --

    def _on_image(self, msg: m.Image, _key: str) -> None:
        self.images.put(msg)

    def _on_faces(self, msg: m.FaceDetections, _key: str) -> None:
        face = followed_box(msg)
        box = None if face is None else (face.x0, face.y0, face.x1, face.y1)
        job = None
        with self._lock:
            self._frame_id, self._faces_ns = msg.frame_id, msg.stamp_ns
            if self.enrolment is not None:
                self.enrolment.offer(msg, self.images.get(msg.stamp_ns))
            track = self.tracks.update(box, msg.stamp_ns, msg.track if face else None)
            if track is None:
                self.vote = None
            elif self.vote is None or self.vote.track != track:
                self.vote = TrackVote(track, self.rules)
            if (face is not None and self.vote is not None and self.index.people
                    and self.embedder is not None and self.inflight is None
                    and self.vote.frame(msg.stamp_ns)):
                image = self.images.get(msg.stamp_ns)
                if image is None or len(face.keypoints) < len(embedding.TEMPLATE):
                    self.vote.failed(msg.stamp_ns)
                    self.node.diagnostics.increment("unpaired_faces")
                else:
                    job = self.inflight = Job(self.vote.track, msg.stamp_ns, image,
                                              keypoints_of(face))
            self._publish(msg.stamp_ns)
        if job is not None:
            self._jobs.put_nowait(job)  # never full: a job is made only when none is in flight

    def _embed_loop(self) -> None:
        try:  # Linux: a thread's own nice value; the face detector goes first on a busy CPU
            os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), EMBED_NICE)
        except (OSError, AttributeError) as exc:
            log.debug("embedding thread keeps its priority: %s", exc)
        while (job := self._jobs.get()) is not None:
            try:
                vector: npt.NDArray[np.float32] | None = self._embed(job.image, job.keypoints)
            except (images.FrameRefused, embedding.BadKeypoints, ValueError) as exc:
                self.node.diagnostics.increment("bad_frames")
                log.debug("frame not embedded: %s", exc)
                vector = None
            except Exception:
                log.exception("embedding failed")
                vector = None
            with self._lock:
                self.inflight = None
                self._answer(job, vector)

    def _embed(self, image: m.Image, keypoints: list[tuple[float, float]]
               ) -> npt.NDArray[np.float32]:
        assert self.embedder is not None
        bgr = images.decode_image(image, images.DEFAULT_MAX_PIXELS)
        with self._net_lock:
            started = time.perf_counter()
            vector = self.embedder.face(bgr, keypoints)
        self.node.diagnostics.values["embed_ms"] = round((time.perf_counter() - started) * 1e3, 1)
        self.node.diagnostics.increment("embeddings")
        return vector

    def _answer(self, job: Job, vector: npt.NDArray[np.float32] | None) -> None:
        """One embedding's result into its track's vote. Under the lock."""
        vote = self.vote
        if vote is None or vote.track != job.track:
            return  # the track ended while its frame was embedded
        if vector is None:
            vote.failed(job.stamp_ns)
            return
        found = self.index.match(vector, self.s.threshold, self.s.margin)
        vote.answer(Answer(job.stamp_ns, found.name, found.score))
        if vote.name is not None and found.name == vote.name and self.gallery is not None:
            self.gallery.seen(vote.name, job.stamp_ns / 1e9)
            self._seen_dirty = True
        self._publish(job.stamp_ns)

    def _publish(self, stamp_ns: int) -> None:
        """Put the followed face's name if track or name changed. Under the lock."""
        vote = self.vote
        track = None if vote is None else vote.track
        name = None if vote is None else vote.name
        if (track, name) == self._published:
            return
        self._published = (track, name)
        score = None if vote is None or vote.score is None else max(-1.0, min(1.0, vote.score))
        self._name_pub.put(m.FaceName(
            stamp_ns=stamp_ns, frame_id=self._frame_id, track=track, name=name, score=score,
            votes=0 if vote is None else min(vote.votes, 1000)))
        if name is not None:
            log.info("track %d is %s", track, name)

    def tick(self) -> None:
        """Lost faces (no faces message at all), last-seen saves, retention."""
        now_ns = m.now_ns()
        with self._lock:
            if self.tracks.track is not None and now_ns - self._faces_ns > self.s.lost_s * 1e9:
                self.tracks.update(None, now_ns)
                if self.tracks.track is None:
                    self.vote = None
                    self._publish(now_ns)
            mono = time.monotonic()
            if self._seen_dirty and mono - self._seen_saved >= self.s.seen_save_s:
                self._seen_dirty = False
                self._seen_saved = mono
                self._save("last-seen times")
            if mono >= self._retention_due:
                self._expire(time.time())
            values = self.node.diagnostics.values
            values["track"] = self.tracks.track or 0
            values["named"] = (self.vote.name or "") if self.vote else ""

    def _expire(self, now_s: float) -> None:
        """Apply `retention_days`. Under the lock."""
        self._retention_due = time.monotonic() + RETENTION_PERIOD_S
        if self.s.retention_days is None or self.gallery is None:
            return
        gone = self.gallery.expire(now_s, self.s.retention_days)
        if gone:
            for name in gone:
                log.info("forgot %s: not seen for %g days (retention)", name,
                         self.s.retention_days)
            self._save("retention")
            self._rebuild()
            self._strike(set(gone))

    def _save(self, why: str) -> str | None:
        """Write the gallery; the error text, or None. Under the lock."""
        if self.gallery is None:
            return "no usable gallery"
        if self.key is None:
            return f"no usable gallery key ({self.key_path})"
        try:
            gallery.save(self.path, self.gallery, self.key)
        except OSError as exc:
            self.node.diagnostics.increment("save_errors")
            log.error("could not save the gallery %s (%s): %s", self.path, why, exc)
            return f"could not save {self.path}: {exc.strerror or exc}"
        return None

    def _strike(self, names: set[str] | None) -> None:
        """Forgotten names leave the followed face's vote at once. Under the lock."""
        if self.vote is not None and self.vote.forget(names):
            self._publish(m.now_ns())

    # -- queries --

    def _refusal(self) -> str | None:
        """Why the gallery must not be written now, or None. Under the lock.

        An unusable file is read again first: the user may have moved or repaired it.
        """
        if self.gallery is None:
            self._load_gallery()
        if self.gallery is None:
            return (f"the gallery {self.path} is unusable ({self.gallery_problem}); it is not "
                    "overwritten: forget --all replaces it with an empty one, or move it away")
        return None

    def enrol(self, req: m.EnrolRequest) -> m.EnrolReply:
        """Collect `samples` frames with exactly one face, embed them, store them:
        an operator's act (the credential), for an asker still waiting, and not
        if a forget (of anyone: the face may be the one forgotten) came after the
        request was sent."""
        started_ns = m.now_ns()
        sent_ns = req.sent_ns or started_ns
        try:
            name = gallery.valid_name(req.name)
        except gallery.BadName as exc:
            return m.EnrolReply(success=False, message=str(exc))
        if not is_operator(req.credential):
            self.node.diagnostics.increment("refused_not_operator")
            log.info("enrol %s refused: no operator credential", name)
            return m.EnrolReply(success=False, message=NOT_OPERATOR)
        left_s = (sent_ns - started_ns) / 1e9 + req.timeout_s
        if left_s <= 0:
            self.node.diagnostics.increment("enrol_abandoned")
            return m.EnrolReply(success=False, message="its asker has given up (sent "
                                f"{(started_ns - sent_ns) / 1e9:.1f} s ago): not enrolled")
        if self.embedder is None:
            return m.EnrolReply(success=False, message=f"no face model: {self.model_problem}")
        with self._lock:
            refused = self._refusal()
            if refused is None and self.gallery is not None and name in self.gallery.people \
                    and not req.replace:
                refused = f"{name!r} is already enrolled (enrol with replace to retake)"
            if refused is None and self.enrolment is not None:
                refused = "another enrolment is running; try again when it ends"
            if refused is not None:
                log.info("enrol %s refused: %s", name, refused)
                return m.EnrolReply(success=False, message=refused)
            taking = self.enrolment = Enrolment(req.samples)
        try:
            taking.done.wait(left_s)
        finally:
            with self._lock:
                self.enrolment = None
        frames = taking.frames[:req.samples]
        if len(frames) < req.samples:
            why = taking.shortfall(req.timeout_s)
            log.info("enrol %s refused: %s", name, why)
            return m.EnrolReply(success=False, message=why)
        try:
            vectors = [self._embed(img, kps) for img, kps in frames]
        except (images.FrameRefused, embedding.BadKeypoints, ValueError) as exc:
            return m.EnrolReply(success=False, message=f"a frame could not be embedded: {exc}")
        return self._store(name, vectors, req.replace, sent_ns)

    def _store(self, name: str, vectors: list[npt.NDArray[np.float32]],
               replace: bool, sent_ns: int = 0) -> m.EnrolReply:
        rows = np.stack(vectors)
        cos = rows @ rows.T
        with self._lock:
            if float(cos.min()) < self.s.threshold:
                why = (f"the {len(vectors)} frames do not look like one person (lowest cosine "
                       f"{float(cos.min()):.3f}): stay still, alone, facing the camera")
                log.info("enrol %s refused: frames disagree", name)
                return m.EnrolReply(success=False, message=why)
            refused = self._refusal()
            if refused is None and sent_ns and sent_ns <= self._last_forget_ns:
                refused = ("a forget came after this request was sent: it wins over every "
                           "enrolment asked before it (the face may be the one forgotten)")
            others = [i for i, n in enumerate(self.index.people) if n != name]
            if refused is None and others:
                probe = rows.mean(axis=0)
                probe /= np.linalg.norm(probe)
                found = self.index.match(probe, self.s.threshold, self.s.margin)
                if found.name is not None and found.name != name:
                    refused = (f"this face is already enrolled as {found.name!r}: forget "
                               "that name first")
            if refused is not None or self.gallery is None:
                log.info("enrol %s refused: %s", name, refused)
                return m.EnrolReply(success=False, message=refused or "no gallery")
            old = self.gallery.people.get(name)
            try:
                person = self.gallery.enrol(name, vectors, time.time(), replace=replace)
            except ValueError as exc:  # BadName too: taken meanwhile, or the gallery is full
                return m.EnrolReply(success=False, message=str(exc))
            error = self._save("enrol")
            if error is not None:
                if old is None:
                    self.gallery.forget(name)
                else:
                    self.gallery.people[name] = old
                return m.EnrolReply(success=False, message=f"not enrolled: {error}")
            self._rebuild()
            log.info("enrolled %s (%d samples%s)", name, len(person.embeddings),
                     ", replacing the old ones" if old is not None else "")
        return m.EnrolReply(success=True, message=f"enrolled {name} from {len(vectors)} frames",
                            name=name, samples=len(person.embeddings))

    def forget(self, req: m.ForgetRequest) -> m.ForgetReply:
        """Erase one person or everybody; the followed face's name goes at once.
        An operator's act (the credential); every enrolment asked
        before it is refused when it comes to storing."""
        if req.all == (req.name is not None):
            return m.ForgetReply(success=False, message="give either a name or all, not both")
        if not is_operator(req.credential):
            self.node.diagnostics.increment("refused_not_operator")
            return m.ForgetReply(success=False, message=NOT_OPERATOR)
        with self._lock:
            self._last_forget_ns = m.now_ns()
            if req.all:
                names = [] if self.gallery is None else sorted(self.gallery.people)
                self.gallery = gallery.Gallery(embedding.MODEL_ID)
                replaced = self.gallery_problem
                self.gallery_problem = None
                self._strike(None)
                error = self._save("forget all")
                self._rebuild()
                if error is not None:
                    return m.ForgetReply(success=False, forgotten=names,
                                         message=f"erased in the running service, {error}")
                log.info("forgot everybody (%d people)%s", len(names),
                         ", replacing the unusable gallery file" if replaced else "")
                return m.ForgetReply(success=True, forgotten=names,
                                     message=f"forgot {len(names)} people")
            refused = self._refusal()
            if refused is not None or self.gallery is None:
                return m.ForgetReply(success=False, message=refused or "no gallery")
            name = (req.name or "").strip()
            if not self.gallery.forget(name):
                return m.ForgetReply(success=False, message=f"nobody named {name!r} is enrolled")
            self._strike({name})
            self._rebuild()
            error = self._save("forget")
            log.info("forgot %s", name)
            if error is not None:
                return m.ForgetReply(success=False, forgotten=[name],
                                     message=f"erased in the running service, {error}")
            return m.ForgetReply(success=True, forgotten=[name], message=f"forgot {name}")

    def list_people(self, _req: m.Trigger) -> m.KnownPeople:
        with self._lock:
            if self._refusal() is not None or self.gallery is None:
                raise gallery.GalleryError(f"the gallery is unusable: {self.gallery_problem}")
            people = [m.KnownPerson(name=p.name, enrolled_ns=int(p.enrolled_s * 1e9),
                                    last_seen_ns=int(p.last_seen_s * 1e9),
                                    samples=len(p.embeddings))
                      for p in sorted(self.gallery.people.values(), key=lambda p: p.name)]
            return m.KnownPeople(people=people, retention_days=self.s.retention_days)


def load_model(path: str | None, ctx: ServiceContext) -> tuple[embedding.Embedder | None,
                                                                str | None]:
    """The embedder, or None and why (the service runs on without names)."""
    try:
        where = resolve_path(ctx.config, path) if path else None
        return embedding.Embedder.load(where), None
    except embedding.ModelNotFound as exc:
        log.error("no face model, running without names: %s", exc)
        return None, str(exc)


def run(ctx: ServiceContext) -> int:
    settings = settings_from(ctx)  # refuse a bad config before connecting
    path = gallery_path(ctx, settings)
    embedder, problem = load_model(settings.model, ctx)
    node = ctx.node()
    service = IdentityService(node, settings, path, embedder, problem)
    try:
        LiveSettings(settings, service.apply_settings).serve(node)
        service.start()
        node.spin()
    finally:
        service.close()
        node.close()
    return 0
