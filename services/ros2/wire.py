"""rmw_zenoh's wire format, as its design doc (rmw_zenoh `docs/design.md`) describes it.

* Data key expressions: `<domain_id>/<fully qualified name without its
  leading '/'>/<DDS type name>/<RIHS01 hash>`, e.g.
  `0/chatter/std_msgs::msg::dds_::String_/RIHS01_df66...`.
* Graph (liveliness) tokens, one per node and per publisher, subscription,
  service server and client, so `ros2 node list` and `ros2 topic list`
  see them: `@ros2_lv/<domain>/<session id>/<node id>/<entity id>/<kind>/
  <enclave>/<namespace>/<node name>[/<name>/<type>/<hash>/<qos>]`, names
  mangled (`/` -> `%`, empty -> `%`). A node's entity id is its node id.
* The attachment on every sample and query: sequence number (int64 LE),
  source timestamp (ns since the epoch, int64 LE), the GID's length (one
  byte, 16) and the 16-byte GID.
* Payloads are CDR with a 4-byte encapsulation header.

Pure functions: the bridge service (next step, docs/ros2.md) declares what
they spell. Anything read from the network is parsed with checks and
refused with `WireError` naming what is wrong.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass, fields
from typing import Literal

PREFIX = "@ros2_lv"
KINDS = ("NN", "MP", "MS", "SS", "SC")
Kind = Literal["NN", "MP", "MS", "SS", "SC"]
"""Node, message publisher, message subscription, service server, service client."""

RELIABLE, BEST_EFFORT = 1, 2
TRANSIENT_LOCAL, VOLATILE = 1, 2
"""rmw's enum numbers, as the QoS chunk of a graph token writes them."""

GID_SIZE = 16
ATTACHMENT_SIZE = 8 + 8 + 1 + GID_SIZE
CDR_LE = b"\x00\x01\x00\x00"
CDR_BE = b"\x00\x00\x00\x00"
"""Encapsulation headers (representation id, options) of plain CDR."""

_TYPE = re.compile(r"^([a-z][a-z0-9_]*)/(msg|srv|action)/([A-Z][A-Za-z0-9]*(?:_[A-Z][A-Za-z]*)?)$")
_DDS_TYPE = re.compile(r"^([a-z][a-z0-9_]*)::(msg|srv|action)::dds_::([A-Za-z0-9_]+)_$")
_NAME_TOKEN = re.compile(r"^[A-Za-z_~{][A-Za-z0-9_{}]*$")
_HASH = re.compile(r"^RIHS01_[0-9a-f]{64}$")


class WireError(ValueError):
    """Input that is not rmw_zenoh's wire format; the message says what is wrong."""


def dds_type_name(ros_type: str) -> str:
    """`std_msgs/msg/String` -> `std_msgs::msg::dds_::String_` (the name rmw_zenoh keys on)."""
    match = _TYPE.match(ros_type)
    if match is None:
        raise WireError(f"not a ROS 2 type name: {ros_type!r}")
    pkg, kind, name = match.groups()
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """The inverse of `dds_type_name`."""
    match = _DDS_TYPE.match(dds_name)
    if match is None:
        raise WireError(f"not a DDS type name: {dds_name!r}")
    pkg, kind, name = match.groups()
    return f"{pkg}/{kind}/{name}"


def check_hash(type_hash: str) -> str:
    if not _HASH.match(type_hash):
        raise WireError(f"not a RIHS01 type hash: {type_hash!r}")
    return type_hash


def check_name(name: str, *, what: str = "name", allow_root: bool = False) -> str:
    """A fully qualified ROS name: `/` then tokens separated by `/` (a namespace
    may be `/` itself when `allow_root`)."""
    if allow_root and name == "/":
        return name
    if not name.startswith("/") or name.endswith("/"):
        raise WireError(f"{what} {name!r} must start with '/' and not end with one")
    for token in name[1:].split("/"):
        if not _NAME_TOKEN.match(token):
            raise WireError(f"{what} {name!r} has an invalid part {token!r}")
    return name


def topic_key(domain_id: int, name: str, ros_type: str, type_hash: str) -> str:
    """The key expression of topic or service `name` (fully qualified)."""
    if not 0 <= domain_id <= 232:
        raise WireError(f"domain id {domain_id} outside 0..232")
    check_name(name)
    return f"{domain_id}/{name[1:]}/{dds_type_name(ros_type)}/{check_hash(type_hash)}"


def mangle(name: str) -> str:
    """A name as one chunk of a graph token: every `/` is `%`; empty is `%`."""
    return name.replace("/", "%") if name else "%"


def unmangle(chunk: str) -> str:
    return "" if chunk == "%" else chunk.replace("%", "/")


@dataclass(frozen=True)
class Qos:
    """The QoS chunk of a graph token: 11 components, None (written empty) for
    rmw_zenoh's default. Values are rmw's enum numbers: reliability 1
    RELIABLE, 2 BEST_EFFORT; durability 1 TRANSIENT_LOCAL, 2 VOLATILE;
    history 1 KEEP_LAST, 2 KEEP_ALL; liveliness 1 AUTOMATIC."""

    reliability: int | None = None
    durability: int | None = None
    history: int | None = None
    depth: int | None = None
    deadline_sec: int | None = None
    deadline_nsec: int | None = None
    lifespan_sec: int | None = None
    lifespan_nsec: int | None = None
    liveliness: int | None = None
    liveliness_lease_sec: int | None = None
    liveliness_lease_nsec: int | None = None

    def format(self) -> str:
        v = ["" if x is None else str(x) for x in (getattr(self, f.name) for f in fields(self))]
        return f"{v[0]}:{v[1]}:{v[2]},{v[3]}:{v[4]},{v[5]}:{v[6]},{v[7]}:{v[8]},{v[9]},{v[10]}"

    @classmethod
    def parse(cls, text: str) -> Qos:
        groups = text.split(":")
        shape = [1, 1, 2, 2, 2, 3]
        parts = [g.split(",") for g in groups]
        if [len(p) for p in parts] != shape:
            raise WireError(f"not a QoS chunk: {text!r}")
        values: list[int | None] = []
        for part in (x for p in parts for x in p):
            if part == "":
                values.append(None)
            elif part.isdigit() and len(part) <= 20:
                values.append(int(part))
            else:
                raise WireError(f"QoS chunk {text!r} has a non-number {part!r}")
        return cls(*values)


@dataclass(frozen=True)
class GraphToken:
    """One liveliness token of the ROS 2 graph. `name`, `type_name` (DDS
    spelling), `type_hash` and `qos` are None for a node (kind NN)."""

    domain_id: int
    session_id: str
    node_id: int
    entity_id: int
    kind: Kind
    enclave: str
    namespace: str
    node_name: str
    name: str | None = None
    type_name: str | None = None
    type_hash: str | None = None
    qos: Qos | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise WireError(f"unknown entity kind {self.kind!r}")
        if not re.fullmatch(r"[0-9a-f]{1,32}", self.session_id):
            raise WireError(f"session id {self.session_id!r} is not a Zenoh id in hex")
        if not _NAME_TOKEN.match(self.node_name):
            raise WireError(f"invalid node name {self.node_name!r}")
        if self.namespace:
            check_name(self.namespace, what="namespace", allow_root=True)
        entity = (self.name, self.type_name, self.type_hash, self.qos)
        if self.kind == "NN":
            if any(x is not None for x in entity):
                raise WireError("a node token has no topic, type, hash or QoS")
            if self.entity_id != self.node_id:
                raise WireError("a node token's entity id is its node id")
        else:
            if any(x is None for x in entity):
                raise WireError(f"a {self.kind} token needs a name, a type, a hash and a QoS")
            check_name(self.name or "")
            ros_type_name(self.type_name or "")
            check_hash(self.type_hash or "")

    def format(self) -> str:
        head = (f"{PREFIX}/{self.domain_id}/{self.session_id}/{self.node_id}/{self.entity_id}/"
                f"{self.kind}/{mangle(self.enclave)}/{mangle(self.namespace)}/{self.node_name}")
        if self.kind == "NN":
            return head
        assert self.name and self.qos
        return (f"{head}/{mangle(self.name)}/{self.type_name}/{self.type_hash}/"
                f"{self.qos.format()}")

    @classmethod
    def parse(cls, key: str) -> GraphToken:
        """A token's key expression as rmw_zenoh writes it; WireError otherwise."""
        chunks = key.split("/")
        if len(chunks) not in (9, 13) or chunks[0] != PREFIX:
            raise WireError(f"not a ROS 2 graph token: {key[:200]!r}")
        for i in (1, 3, 4):
            if not chunks[i].isdigit() or len(chunks[i]) > 10:
                raise WireError(f"graph token {key[:200]!r}: chunk {i} is not a number")
        kind = chunks[5]
        if kind not in KINDS or (kind == "NN") != (len(chunks) == 9):
            raise WireError(f"graph token {key[:200]!r}: kind {kind!r} with "
                            f"{len(chunks)} chunks")
        extra: dict[str, object] = {}
        if len(chunks) == 13:
            extra = {"name": unmangle(chunks[9]), "type_name": chunks[10],
                     "type_hash": chunks[11], "qos": Qos.parse(chunks[12])}
        return cls(domain_id=int(chunks[1]), session_id=chunks[2], node_id=int(chunks[3]),
                   entity_id=int(chunks[4]), kind=kind,  # type: ignore[arg-type]
                   enclave=unmangle(chunks[6]), namespace=unmangle(chunks[7]),
                   node_name=chunks[8], **extra)  # type: ignore[arg-type]


def entities_key(domain_id: int, kind: Kind, name: str, type_name: str, type_hash: str) -> str:
    """The liveliness key expression matching every `kind` entity (e.g. every
    subscription, `MS`) on topic `name` with that type and hash, in any session,
    node, enclave and namespace and with any QoS."""
    check_name(name)
    ros_type_name(type_name)
    check_hash(type_hash)
    return f"{PREFIX}/{domain_id}/*/*/*/{kind}/*/*/*/{mangle(name)}/{type_name}/{type_hash}/*"


@dataclass(frozen=True)
class Attachment:
    """The metadata rmw_zenoh attaches to every sample, request and reply."""

    sequence: int
    timestamp_ns: int
    gid: bytes

    def encode(self) -> bytes:
        if len(self.gid) != GID_SIZE:
            raise WireError(f"a GID has {GID_SIZE} bytes, not {len(self.gid)}")
        return struct.pack("<qqB", self.sequence, self.timestamp_ns, GID_SIZE) + self.gid

    @classmethod
    def decode(cls, data: bytes | memoryview) -> Attachment:
        data = bytes(data)
        if len(data) != ATTACHMENT_SIZE:
            raise WireError(f"attachment of {len(data)} bytes, expected {ATTACHMENT_SIZE}")
        sequence, timestamp_ns, gid_size = struct.unpack_from("<qqB", data)
        if gid_size != GID_SIZE:
            raise WireError(f"attachment GID length {gid_size}, expected {GID_SIZE}")
        return cls(sequence, timestamp_ns, data[17:])


def encapsulation(payload: bytes | memoryview) -> Literal["CDR_LE", "CDR_BE"]:
    """The CDR flavour a payload's 4-byte header announces; WireError for any other."""
    head = bytes(payload[:4])
    if len(head) < 4:
        raise WireError(f"CDR payload of {len(payload)} bytes has no encapsulation header")
    if head[:2] == CDR_LE[:2]:
        return "CDR_LE"
    if head[:2] == CDR_BE[:2]:
        return "CDR_BE"
    raise WireError(f"unsupported CDR encapsulation {head[:2].hex()} (plain CDR only)")
