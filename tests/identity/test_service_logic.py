"""The identity service's logic on a fake node and a fake embedder (no Zenoh, no model):
names on change only, a stale embedding of a lost track dropped, a forgotten name struck
in the same step, a bad gallery refused and replaced only by forget all, last-seen saved
at a bounded rate."""

from __future__ import annotations

import threading
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from buddybot.contract import keys
from buddybot.contract import messages as m
from buddybot.identity import embedding, gallery
from buddybot.identity.service import IdentityService, Job
from buddybot.identity.settings import IdentitySettings
from buddybot.tools.testing import FakeDiagnostics, RecordingPublisher
from tests.identity.conftest import OPERATOR, key

S = 1_000_000_000
T0 = 1_700_000_000 * S
KEYPOINTS = [m.PixelPoint(x=x, y=y) for x, y in ((3, 3), (6, 3), (4.5, 5), (4.5, 7))]

Enrol = partial(m.EnrolRequest, credential=OPERATOR)
"""A request as the operator makes it."""
Forget = partial(m.ForgetRequest, credential=OPERATOR)


def _vector(seed: int) -> np.ndarray:
    return embedding.unit(np.random.default_rng(seed).normal(size=embedding.DIM))


class FakeNode:
    def __init__(self) -> None:
        self.out: list[m.FaceName] = []
        self.diagnostics = FakeDiagnostics()

    def publisher(self, topic: keys.Topic, /, **_params: str) -> RecordingPublisher:
        assert topic is keys.FACE_NAME
        return RecordingPublisher(self.out)


class FakeEmbedder:
    """Gives the vector of the person the test says is in front of the camera."""

    def __init__(self) -> None:
        self.who = 1

    def face(self, _bgr: np.ndarray, _keypoints: Any) -> np.ndarray:
        return _vector(self.who)


def _service(tmp_path: Path, **settings: Any) -> tuple[IdentityService, FakeNode]:
    node = FakeNode()
    fields = {"votes_needed": 2, "vote_window": 3, "every_nth": 1, **settings}
    service = IdentityService(node, IdentitySettings(**fields),  # type: ignore[arg-type]
                              tmp_path / "gallery.bin", FakeEmbedder(), None)  # type: ignore[arg-type]
    return service, node


def _enrolled(tmp_path: Path, **people: int) -> None:
    g = gallery.Gallery(embedding.MODEL_ID)
    for name, seed in people.items():
        g.enrol(name, [_vector(seed)], T0 / S)
    gallery.save(tmp_path / "gallery.bin", g, key())


def _frame(service: IdentityService, stamp: int, x: float = 0.0) -> None:
    """One frame with the followed face at `x` (image first, then its faces); the
    embedding it asks for, if any, is done at once."""
    service.images.put(m.Image(stamp_ns=stamp, frame_id="front", width=8, height=8,
                               encoding="bgr8", data=bytes(8 * 8 * 3)))
    face = m.FaceBox(x0=x, y0=0, x1=x + 8, y1=8, score=0.9, keypoints=KEYPOINTS, followed=True)
    service._on_faces(m.FaceDetections(stamp_ns=stamp, frame_id="front", width=8, height=8,
                                       faces=[face]), "camera/front/faces")
    job = service.inflight
    if job is not None:  # what the embedding thread does, here at once
        assert service._jobs.get_nowait() is job
        service.inflight = None
        service._answer(job, service._embed(job.image, job.keypoints))


def _frames(service: IdentityService, count: int, start: int = T0) -> None:
    for i in range(count):
        _frame(service, start + i * S // 30)


def _said(node: FakeNode) -> list[tuple[int | None, str | None]]:
    return [(n.track, n.name) for n in node.out]


def test_a_name_after_the_vote_published_on_change_only(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1, bob=2)
    service, node = _service(tmp_path)
    service.prepare()
    _frames(service, 5)
    assert _said(node) == [(None, None), (1, None), (1, "ada")]
    assert node.out[-1].votes == 2 and node.out[-1].score == pytest.approx(1.0, abs=1e-5)


def test_a_stranger_stays_unknown(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1)
    service, node = _service(tmp_path)
    service.prepare()
    service.embedder.who = 9  # type: ignore[union-attr]
    _frames(service, 10)
    assert _said(node) == [(None, None), (1, None)]


def test_an_embedding_of_a_lost_track_does_not_name_the_next(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1)
    service, _node = _service(tmp_path)
    service.prepare()
    _frame(service, T0)
    stale = Job(1, T0 + 1, service.images.get(T0), [(3.0, 3.0)] * 4)  # type: ignore[arg-type]
    _frame(service, T0 + 2, x=500.0)  # the followed face jumped: track 2
    service._answer(stale, _vector(1))
    assert service.vote is not None and service.vote.track == 2
    assert [a.stamp_ns for a in service.vote.answers] == [T0 + 2]


def test_forget_strikes_the_name_of_the_followed_face_at_once(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1, bob=2)
    service, node = _service(tmp_path)
    service.prepare()
    _frames(service, 3)
    assert _said(node)[-1] == (1, "ada")
    reply = service.forget(Forget(name="ada"))
    assert reply.success and reply.forgotten == ["ada"]
    assert _said(node)[-1] == (1, None)
    assert list(gallery.load(tmp_path / "gallery.bin", embedding.MODEL_ID, key()).people) == ["bob"]
    assert not service.forget(Forget(name="ada")).success
    assert not service.forget(Forget(name="bob", all=True)).success


def test_no_face_for_lost_s_ends_the_track(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1)
    service, node = _service(tmp_path, lost_s=0.5)
    service.prepare()
    _frame(service, T0)
    empty = m.FaceDetections(stamp_ns=T0 + S, frame_id="front", width=8, height=8)
    service._on_faces(empty, "camera/front/faces")
    assert _said(node)[-1] == (None, None)


@pytest.mark.parametrize("content", [b"garbage", b"BUDDYBOT-GALLERY 1\n" + b"\0" * 40])
def test_a_bad_gallery_means_no_names_and_is_only_replaced_by_forget_all(
        tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "gallery.bin"
    path.write_bytes(content)
    path.chmod(0o600)
    service, node = _service(tmp_path)
    service.prepare()
    assert node.diagnostics.level == "ERROR" and "no names" in node.diagnostics.message
    _frames(service, 5)
    assert all(n.name is None for n in node.out)
    reply = service.forget(Forget(name="ada"))
    assert not reply.success and "not overwritten" in reply.message
    assert path.read_bytes() == content
    with pytest.raises(gallery.GalleryError, match="unusable"):
        service.list_people(m.Trigger())
    assert service.forget(Forget(all=True)).success
    assert node.diagnostics.level == "OK"
    assert gallery.load(path, embedding.MODEL_ID, key()).people == {}


def test_a_gallery_others_may_write_is_refused(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1)
    (tmp_path / "gallery.bin").chmod(0o666)
    service, node = _service(tmp_path)
    service.prepare()
    assert node.diagnostics.level == "ERROR" and "accessible to others" in node.diagnostics.message
    assert service.index.people == ()


def test_last_seen_is_saved_at_a_bounded_rate(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1)
    service, _node = _service(tmp_path, seen_save_s=3600.0)
    service.prepare()
    _frames(service, 3, start=T0 + 100 * S)
    saved = gallery.load(tmp_path / "gallery.bin", embedding.MODEL_ID, key())
    assert saved.people["ada"].last_seen_s == T0 / S  # not yet: within seen_save_s
    service.close()
    saved = gallery.load(tmp_path / "gallery.bin", embedding.MODEL_ID, key())
    assert saved.people["ada"].last_seen_s > T0 / S + 99


def _enrol_while_frames(service: IdentityService, request: m.EnrolRequest,
                        faces: int = 1) -> m.EnrolReply:
    """Run an enrolment on a thread while frames with `faces` faces come in."""
    replies: list[m.EnrolReply] = []
    worker = threading.Thread(target=lambda: replies.append(service.enrol(request)))
    worker.start()
    stamp = T0 + 500 * S
    while worker.is_alive():
        stamp += S // 30
        service.images.put(m.Image(stamp_ns=stamp, frame_id="front", width=8, height=8,
                                   encoding="bgr8", data=bytes(8 * 8 * 3)))
        boxes = [m.FaceBox(x0=i * 10.0, y0=0, x1=i * 10.0 + 8, y1=8, score=0.9,
                           keypoints=KEYPOINTS, followed=i == 0) for i in range(faces)]
        service._on_faces(m.FaceDetections(stamp_ns=stamp, frame_id="front", width=8,
                                           height=8, faces=boxes), "camera/front/faces")
        worker.join(0.01)
    return replies[0]


def test_enrol_stores_embeddings_and_refuses_what_it_must(tmp_path: Path) -> None:
    _enrolled(tmp_path, ada=1)
    service, _node = _service(tmp_path)
    service.prepare()
    service.embedder.who = 7  # type: ignore[union-attr]
    for bad in ("bad\x00name", " "):
        reply = service.enrol(Enrol(name=bad))
        assert not reply.success and "name" in reply.message
    reply = _enrol_while_frames(service, Enrol(name="ada", timeout_s=0.2))
    assert not reply.success and "already enrolled" in reply.message
    reply = _enrol_while_frames(service, Enrol(name="cy", timeout_s=0.3), faces=2)
    assert not reply.success and "more than one face" in reply.message
    reply = _enrol_while_frames(service, Enrol(name="cy", samples=3, timeout_s=10))
    assert reply.success and reply.samples == 3
    saved = gallery.load(tmp_path / "gallery.bin", embedding.MODEL_ID, key())
    assert sorted(saved.people) == ["ada", "cy"] and len(saved.people["cy"].embeddings) == 3
    service.embedder.who = 1  # type: ignore[union-attr]
    reply = _enrol_while_frames(service, Enrol(name="dee", samples=2, timeout_s=10))
    assert not reply.success and "already enrolled as 'ada'" in reply.message


def test_enrol_and_forget_are_an_operators_acts_and_a_forget_wins(tmp_path: Path) -> None:
    """The attacks: 300 enrolments from a client that gave up (16 stayed queued), and one
    of them enrolled Ada's face as "flood1" 3 ms after `forget Ada`; none needed an
    operator. Now each needs the operator secret, one whose asker gave up is dropped,
    and a forget wins over every enrolment asked before it."""
    _enrolled(tmp_path, ada=1)
    service, node = _service(tmp_path)
    service.prepare()
    service.embedder.who = 7  # type: ignore[union-attr]
    for credential in ("", "guessed"):
        refused = service.enrol(m.EnrolRequest(name="flood1", credential=credential))
        assert not refused.success and "operator" in refused.message
        gone = service.forget(m.ForgetRequest(name="ada", credential=credential))
        assert not gone.success and "operator" in gone.message
    assert node.diagnostics.values["refused_not_operator"] == 4
    stale = service.enrol(Enrol(name="late", timeout_s=5.0, sent_ns=m.now_ns() - 6 * S))
    assert not stale.success and "given up" in stale.message
    asked = m.now_ns()  # asked (under another name), then Ada is forgotten: queued behind
    reply: list[m.EnrolReply] = []
    worker = threading.Thread(target=lambda: reply.append(_enrol_while_frames(
        service, Enrol(name="flood1", samples=3, timeout_s=10, sent_ns=asked))))
    assert service.forget(Forget(name="ada")).success
    worker.start()
    worker.join(60)
    assert not reply[0].success and "a forget came after this request" in reply[0].message
    assert "ada" not in gallery.load(tmp_path / "gallery.bin", embedding.MODEL_ID, key()).people
    later = _enrol_while_frames(service, Enrol(name="ada", samples=3, timeout_s=10,
                                               sent_ns=m.now_ns()))
    assert later.success, later.message  # asked after the forget: a new consent


def test_enrol_without_the_model_says_how_to_install_it(tmp_path: Path) -> None:
    node = FakeNode()
    service = IdentityService(node, IdentitySettings(), tmp_path / "g.bin",  # type: ignore[arg-type]
                              None, "not found; install the face identity model with: pip ...")
    service.prepare()
    assert node.diagnostics.level == "ERROR" and "install" in node.diagnostics.message
    reply = service.enrol(Enrol(name="ada"))
    assert not reply.success and "install" in reply.message


def test_a_bad_gallery_moved_away_is_noticed_at_the_next_request(tmp_path: Path) -> None:
    path = tmp_path / "gallery.bin"
    path.write_bytes(b"garbage")
    path.chmod(0o600)
    service, node = _service(tmp_path)
    service.prepare()
    assert node.diagnostics.level == "ERROR"
    path.rename(tmp_path / "gallery.bad")
    assert service.list_people(m.Trigger()).people == []
    assert node.diagnostics.level == "OK"
    assert (tmp_path / "gallery.bad").read_bytes() == b"garbage"
