"""rmw_zenoh's wire format: key expressions, liveliness tokens, QoS strings, attachments, GIDs.

Pure functions, no zenoh import. Source of truth: ros2/rmw_zenoh ``docs/design.md`` at commit
99a6a2bd10b949052f4f12c5854825dc005e95a5, and the code it describes
(``rmw_zenoh_cpp/src/detail/liveliness_utils.cpp`` at 3411fdec, ``qos.cpp`` at 5e10d47b,
``attachment_helpers.cpp`` at 534747dc, ``type_support_common.hpp`` at 24948712).

- Topic key: ``<domain>/<topic without leading/trailing '/'>/<pkg>::msg::dds_::<Type>_/<RIHS01_…>``.
- Liveliness token (node):
  ``@ros2_lv/<domain>/<zid>/<node_id>/<node_id>/NN/<enclave>/<namespace>/<node>``.
- Liveliness token (endpoint): same prefix with the entity id and kind (MP, MS, SS, SC), then
  ``/<topic>/<dds type>/<type hash>/<qos>``. Names are mangled: every ``/`` becomes ``%``.
- GID: XXH3-128 of the token string, low 64 bits then high 64 bits, little-endian.
- Attachment (33 bytes): sequence int64 LE, source time ns int64 LE, 0x10, 16-byte GID.
"""

from __future__ import annotations

import enum
import re
import struct
from dataclasses import dataclass, replace

import xxhash

ADMIN_SPACE = "@ros2_lv"
SLASH_REPLACEMENT = "%"
GID_SIZE = 16
ATTACHMENT_SIZE = 8 + 8 + 1 + GID_SIZE
_ATTACHMENT = struct.Struct("<qqB16s")


class EntityKind(enum.StrEnum):
    """Liveliness entity kinds (``liveliness_utils.cpp``: NODE_STR, PUB_STR, ...)."""

    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(enum.IntEnum):
    """``rmw_qos_reliability_policy_e`` (rmw/types.h)."""

    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class Durability(enum.IntEnum):
    """``rmw_qos_durability_policy_e`` (rmw/types.h)."""

    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2
    UNKNOWN = 3
    BEST_AVAILABLE = 4


class History(enum.IntEnum):
    """``rmw_qos_history_policy_e`` (rmw/types.h)."""

    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2
    UNKNOWN = 3


class Liveliness(enum.IntEnum):
    """``rmw_qos_liveliness_policy_e`` (rmw/types.h)."""

    SYSTEM_DEFAULT = 0
    AUTOMATIC = 1
    MANUAL_BY_NODE = 2
    MANUAL_BY_TOPIC = 3
    UNKNOWN = 4
    BEST_AVAILABLE = 5


#: ``RMW_DURATION_INFINITE`` (rmw/time.h) as (sec, nsec).
DURATION_INFINITE = (9223372036, 854775807)


@dataclass(frozen=True)
class Qos:
    """A QoS profile as rmw_zenoh encodes it. Defaults are rmw_zenoh's (``qos.cpp``)."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 42
    deadline: tuple[int, int] = DURATION_INFINITE
    lifespan: tuple[int, int] = DURATION_INFINITE
    liveliness: Liveliness = Liveliness.AUTOMATIC
    liveliness_lease: tuple[int, int] = DURATION_INFINITE


#: rmw_zenoh's default profile; fields equal to it are left empty in the QoS string.
DEFAULT_QOS = Qos()
#: rclcpp/rclpy default publisher/subscription profile (keep last 10, reliable, volatile).
QOS_DEFAULT_10 = Qos(depth=10)
#: ``rmw_qos_profile_sensor_data``: best effort, keep last 5, volatile.
QOS_SENSOR_DATA = Qos(reliability=Reliability.BEST_EFFORT, depth=5)
#: tf2_ros TransformBroadcaster/Listener on /tf: keep last 100, reliable, volatile.
QOS_TF = Qos(depth=100)


def adapt_qos(qos: Qos) -> Qos:
    """Resolve SYSTEM_DEFAULT/UNKNOWN and depth 0 as rmw_zenoh does (``QoS::best_available_qos``).

    Also maps the rmw ``*_DEFAULT`` durations ((0, 0), "unspecified") to infinite.
    """
    d = DEFAULT_QOS
    out = qos
    if out.history in (History.SYSTEM_DEFAULT, History.UNKNOWN):
        out = replace(out, history=d.history)
    if out.depth == 0:
        out = replace(out, depth=d.depth)
    if out.reliability in (Reliability.SYSTEM_DEFAULT, Reliability.UNKNOWN):
        out = replace(out, reliability=d.reliability)
    if out.durability in (Durability.SYSTEM_DEFAULT, Durability.UNKNOWN):
        out = replace(out, durability=d.durability)
    if out.liveliness in (Liveliness.SYSTEM_DEFAULT, Liveliness.UNKNOWN):
        out = replace(out, liveliness=d.liveliness)
    for name in ("deadline", "lifespan", "liveliness_lease"):
        if getattr(out, name) == (0, 0):
            out = replace(out, **{name: DURATION_INFINITE})
    return out


def _field(value: int, default: int) -> str:
    return "" if value == default else str(int(value))


def qos_to_keyexpr(qos: Qos) -> str:
    """Compact QoS string of a liveliness token (``qos_to_keyexpr`` in liveliness_utils.cpp).

    Format ``rel:dur:hist,depth:dl_s,dl_ns:life_s,life_ns:live,lease_s,lease_ns`` (deadline,
    lifespan, liveliness kind and lease duration) with every field that equals rmw_zenoh's
    default left empty, e.g. ``::,10:,:,:,,``.
    Pass the *adapted* profile (see :func:`adapt_qos`), as rmw_zenoh does.
    """
    d = DEFAULT_QOS
    return (
        f"{_field(qos.reliability, d.reliability)}:"
        f"{_field(qos.durability, d.durability)}:"
        f"{_field(qos.history, d.history)},{_field(qos.depth, d.depth)}:"
        f"{_field(qos.deadline[0], d.deadline[0])},{_field(qos.deadline[1], d.deadline[1])}:"
        f"{_field(qos.lifespan[0], d.lifespan[0])},{_field(qos.lifespan[1], d.lifespan[1])}:"
        f"{_field(qos.liveliness, d.liveliness)},"
        f"{_field(qos.liveliness_lease[0], d.liveliness_lease[0])},"
        f"{_field(qos.liveliness_lease[1], d.liveliness_lease[1])}"
    )


def keyexpr_to_qos(text: str) -> Qos:
    """Parse a QoS string (``keyexpr_to_qos``); empty fields take rmw_zenoh's defaults.

    Raises ValueError on a malformed string.
    """
    parts = text.split(":")
    if len(parts) < 6:
        raise ValueError(f"QoS string needs 6 ':'-separated parts: {text!r}")
    hist, deadline, lifespan, live = (p.split(",") for p in parts[2:6])
    if len(hist) < 2 or len(deadline) < 2 or len(lifespan) < 2 or len(live) < 3:
        raise ValueError(f"QoS string has too few ',' fields: {text!r}")
    d = DEFAULT_QOS

    def num(s: str, default: int) -> int:
        return default if s == "" else int(s)

    return Qos(
        reliability=Reliability(num(parts[0], d.reliability)),
        durability=Durability(num(parts[1], d.durability)),
        history=History(num(hist[0], d.history)),
        depth=num(hist[1], d.depth),
        deadline=(num(deadline[0], d.deadline[0]), num(deadline[1], d.deadline[1])),
        lifespan=(num(lifespan[0], d.lifespan[0]), num(lifespan[1], d.lifespan[1])),
        liveliness=Liveliness(num(live[0], d.liveliness)),
        liveliness_lease=(num(live[1], d.liveliness_lease[0]), num(live[2], d.liveliness_lease[1])),
    )


def mangle_name(name: str) -> str:
    """Replace every ``/`` with ``%`` (``mangle_name``). An empty name stays empty."""
    return name.replace("/", SLASH_REPLACEMENT)


def demangle_name(name: str) -> str:
    """Replace every ``%`` with ``/`` (``demangle_name``)."""
    return name.replace(SLASH_REPLACEMENT, "/")


def dds_type_name(ros_type: str) -> str:
    """``sensor_msgs/msg/Image`` -> ``sensor_msgs::msg::dds_::Image_`` (``_create_type_name``)."""
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts):
        raise ValueError(f"expected 'pkg/msg/Type', got {ros_type!r}")
    pkg, kind, name = parts
    return f"{pkg}::{kind}::dds_::{name}_"


def ros_type_name(dds_name: str) -> str:
    """Inverse of :func:`dds_type_name`: ``pkg::msg::dds_::Type_`` -> ``pkg/msg/Type``."""
    head, sep, tail = dds_name.partition("::dds_::")
    if not sep or not tail.endswith("_"):
        raise ValueError(f"not a DDS type name: {dds_name!r}")
    return f"{head.replace('::', '/')}/{tail[:-1]}"


def fully_qualified_name(name: str, namespace: str = "/") -> str:
    """Resolve a relative topic name against a node namespace (no ``~`` or substitutions)."""
    if name.startswith("/"):
        return name
    ns = namespace.rstrip("/")
    return f"{ns}/{name}" if ns else f"/{name}"


_NODE_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")
_NAME_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


def validate_node_name(name: str) -> str:
    """Return ``name`` if it is a valid ROS 2 node name (``rmw_validate_node_name``: letters,
    digits, ``_``; not starting with a digit), else raise ValueError (e.g. ``gngdt_cam-0``)."""
    if not _NODE_NAME.fullmatch(name):
        raise ValueError(f"invalid ROS 2 node name {name!r}: use [A-Za-z_][A-Za-z0-9_]*")
    return name


def validate_topic_name(name: str) -> str:
    """Return a fully qualified topic name if valid (``rmw_validate_full_topic_name``: starts
    with ``/``, tokens of letters, digits and ``_`` not starting with a digit, no ``//``, no
    trailing ``/``), else raise ValueError."""
    tokens = name.split("/")
    if len(tokens) < 2 or tokens[0] != "" or not all(_NAME_TOKEN.fullmatch(t) for t in tokens[1:]):
        raise ValueError(f"invalid fully qualified ROS 2 topic name {name!r}")
    return name


def topic_keyexpr(domain_id: int, topic: str, ros_type: str, type_hash: str) -> str:
    """Data key expression of a topic (``TopicInfo`` in liveliness_utils.cpp).

    ``topic`` is the fully qualified name; leading and trailing ``/`` are stripped.
    ``type_hash`` is the ``RIHS01_<64 hex>`` string.
    """
    name = topic.strip("/")
    if not name:
        raise ValueError("empty topic name")
    return f"{domain_id}/{name}/{dds_type_name(ros_type)}/{type_hash}"


@dataclass(frozen=True)
class NodeInfo:
    """What every token of a node carries. ``zid`` is ``str(session.info.zid())``."""

    domain_id: int
    zid: str
    node_id: int
    name: str
    namespace: str = "/"
    enclave: str = "/"


def _chunk(name: str) -> str:
    # rcl gives "/" for an empty namespace/enclave; rmw_zenoh mangles it to "%".
    return mangle_name(name or "/")


def node_token(node: NodeInfo) -> str:
    """Liveliness key expression of a node (entity kind NN, entity id = node id)."""
    return "/".join(
        [
            ADMIN_SPACE,
            str(node.domain_id),
            node.zid,
            str(node.node_id),
            str(node.node_id),
            EntityKind.NODE.value,
            _chunk(node.enclave),
            _chunk(node.namespace),
            mangle_name(node.name),
        ]
    )


def endpoint_token(
    node: NodeInfo,
    entity_id: int,
    kind: EntityKind,
    topic: str,
    ros_type: str,
    type_hash: str,
    qos: Qos,
) -> str:
    """Liveliness key expression of a publisher (MP), subscription (MS), service (SS), client (SC).

    ``topic`` is the fully qualified name (mangled: ``/camera/points`` -> ``%camera%points``);
    ``qos`` should already be adapted (:func:`adapt_qos`).
    """
    if kind is EntityKind.NODE:
        raise ValueError("use node_token() for nodes")
    return "/".join(
        [
            ADMIN_SPACE,
            str(node.domain_id),
            node.zid,
            str(node.node_id),
            str(entity_id),
            kind.value,
            _chunk(node.enclave),
            _chunk(node.namespace),
            mangle_name(node.name),
            mangle_name(topic),
            mangle_name(dds_type_name(ros_type)),
            mangle_name(type_hash),
            qos_to_keyexpr(qos),
        ]
    )


@dataclass(frozen=True)
class TokenInfo:
    """A parsed liveliness token. Topic fields are None for nodes."""

    domain_id: int
    zid: str
    node_id: str
    entity_id: str
    kind: EntityKind
    enclave: str
    namespace: str
    node_name: str
    topic: str | None = None
    ros_type: str | None = None
    type_hash: str | None = None
    qos: Qos | None = None


def parse_token(key: str) -> TokenInfo:
    """Parse a liveliness key expression (``Entity::make(keyexpr)``). Raises ValueError."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE or any(p == "" for p in parts):
        raise ValueError(f"not an rmw_zenoh liveliness token: {key!r}")
    kind = EntityKind(parts[5])
    info = TokenInfo(
        domain_id=int(parts[1]),
        zid=parts[2],
        node_id=parts[3],
        entity_id=parts[4],
        kind=kind,
        enclave=demangle_name(parts[6]),
        namespace=demangle_name(parts[7]),
        node_name=demangle_name(parts[8]),
    )
    if kind is EntityKind.NODE:
        return info
    if len(parts) < 13:
        raise ValueError(f"endpoint token without topic fields: {key!r}")
    return replace(
        info,
        topic=demangle_name(parts[9]),
        ros_type=ros_type_name(demangle_name(parts[10])),
        type_hash=demangle_name(parts[11]),
        qos=keyexpr_to_qos(parts[12]),
    )


def gid_from_token(token: str) -> bytes:
    """16-byte entity GID: XXH3-128 (seed 0) of the token string, its low 64 bits then its high
    64 bits, each little-endian (``memcpy`` of ``XXH128_hash_t``'s ``low64``, ``high64`` on a
    little-endian machine), i.e. xxhash's canonical big-endian digest reversed."""
    return xxhash.xxh3_128_digest(token.encode())[::-1]


@dataclass(frozen=True)
class Attachment:
    """The metadata rmw_zenoh sends with every sample (``AttachmentData``)."""

    sequence_number: int
    source_timestamp_ns: int
    gid: bytes


def encode_attachment(sequence_number: int, source_timestamp_ns: int, gid: bytes) -> bytes:
    """33 bytes: int64 LE sequence, int64 LE source time (ns since epoch), 0x10, 16-byte GID.

    That is zenoh-ext serialization of (int64, int64, std::array<uint8_t, 16>): the array is
    prefixed by its length as a LEB128 varint (16 -> 0x10).
    """
    if len(gid) != GID_SIZE:
        raise ValueError(f"GID must be {GID_SIZE} bytes, got {len(gid)}")
    return _ATTACHMENT.pack(sequence_number, source_timestamp_ns, GID_SIZE, gid)


def decode_attachment(data: bytes) -> Attachment:
    """Parse a 33-byte rmw_zenoh attachment. Raises ValueError on any other layout."""
    if len(data) != ATTACHMENT_SIZE:
        raise ValueError(f"attachment must be {ATTACHMENT_SIZE} bytes, got {len(data)}")
    seq, stamp, gid_len, gid = _ATTACHMENT.unpack(data)
    if gid_len != GID_SIZE:
        raise ValueError(f"attachment GID length byte must be {GID_SIZE}, got {gid_len}")
    return Attachment(seq, stamp, gid)


class EntityIds:
    """Context-wide id counter: rmw_zenoh numbers nodes and their entities from one counter
    starting at 0 (``rmw_context_impl_s::get_next_entity_id``)."""

    def __init__(self) -> None:
        self._next = 0

    def next(self) -> int:
        """Return the next unused id."""
        value = self._next
        self._next += 1
        return value


def liveliness_subscription_key(domain_id: int) -> str:
    """Key expression that matches every token of a domain (``subscription_token``)."""
    return f"{ADMIN_SPACE}/{domain_id}/**"
