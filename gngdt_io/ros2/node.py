"""A ROS 2 node on a zenoh session, speaking rmw_zenoh's wire format (no ROS installation).

The node declares liveliness tokens for itself and for every publisher and subscription, so
ROS 2's graph (``ros2 node list``, ``ros2 topic list/info``) sees them; publishers attach the
33-byte rmw_zenoh attachment to every sample. Payloads are CDR bytes (`gngdt.io.ros2.messages`).

A TRANSIENT_LOCAL subscription (``/tf_static``) is a zenoh advanced subscriber that asks late
publishers for their history, as rmw_zenoh's is; publishers are plain zenoh publishers, so a
TRANSIENT_LOCAL publisher (a late joiner's history) is not offered.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable

import zenoh

from gngdt.io.ros2.wire import (
    QOS_DEFAULT_10,
    Attachment,
    Durability,
    EntityIds,
    EntityKind,
    History,
    NodeInfo,
    Qos,
    Reliability,
    adapt_qos,
    decode_attachment,
    encode_attachment,
    endpoint_token,
    fully_qualified_name,
    gid_from_token,
    node_token,
    topic_keyexpr,
    validate_node_name,
    validate_topic_name,
)

log = logging.getLogger(__name__)

#: subscriptions hear other sessions only: a node never takes back what it published itself
#: (rclcpp's ignore_local_publications), e.g. gngdt's own /tf into its pose lookups
REMOTE = zenoh.Locality.REMOTE
#: callback(payload CDR bytes, attachment or None if absent/malformed)
SampleCallback = Callable[[bytes, Attachment | None], None]


class _Endpoint:
    """What names a ROS 2 publisher or subscription on zenoh: its (validated) topic, type and
    QoS, the topic key expression, its liveliness token and GID."""

    def __init__(self, node: NodeInfo, entity_id: int, kind: EntityKind, topic: str,
                 ros_type: str, type_hash: str, qos: Qos) -> None:
        self.topic = validate_topic_name(topic)
        self.ros_type = ros_type
        self.qos = adapt_qos(qos)
        self.key = topic_keyexpr(node.domain_id, topic, ros_type, type_hash)
        self.token_key = endpoint_token(node, entity_id, kind, topic, ros_type, type_hash,
                                        self.qos)
        self.gid = gid_from_token(self.token_key)


class Ros2Publisher(_Endpoint):
    """One ROS 2 publisher: a zenoh publisher on the topic key plus an MP liveliness token."""

    def __init__(
        self,
        session: zenoh.Session,
        node: NodeInfo,
        entity_id: int,
        topic: str,
        ros_type: str,
        type_hash: str,
        qos: Qos,
    ) -> None:
        super().__init__(node, entity_id, EntityKind.PUBLISHER, topic, ros_type, type_hash, qos)
        reliable = self.qos.reliability == Reliability.RELIABLE
        block = reliable and self.qos.history == History.KEEP_ALL
        self._pub = session.declare_publisher(
            self.key,
            reliability=zenoh.Reliability.RELIABLE if reliable else zenoh.Reliability.BEST_EFFORT,
            congestion_control=(
                zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
            ),
        )
        self._token = session.liveliness().declare_token(self.token_key)
        self._seq = 1  # rmw_zenoh's PublisherData starts at 1
        self._lock = threading.Lock()

    @property
    def has_subscribers(self) -> bool:
        """A subscriber matches (zenoh's matching status): worth encoding for."""
        return bool(self._pub.matching_status.matching)

    def publish(self, cdr: bytes, source_time_ns: int | None = None) -> None:
        """Put one CDR payload with the rmw_zenoh attachment (sequence, source time, GID)."""
        with self._lock:
            seq = self._seq
            self._seq += 1
        stamp = time.time_ns() if source_time_ns is None else int(source_time_ns)
        self._pub.put(cdr, attachment=encode_attachment(seq, stamp, self.gid))

    def close(self) -> None:
        """Undeclare the token and the publisher."""
        self._token.undeclare()
        self._pub.undeclare()


class Ros2Subscription(_Endpoint):
    """One ROS 2 subscription: a zenoh subscriber on the topic key (samples from other sessions
    only) plus an MS token."""

    def __init__(
        self,
        session: zenoh.Session,
        node: NodeInfo,
        entity_id: int,
        topic: str,
        ros_type: str,
        type_hash: str,
        qos: Qos,
        callback: SampleCallback,
    ) -> None:
        super().__init__(node, entity_id, EntityKind.SUBSCRIPTION, topic, ros_type, type_hash,
                         qos)
        self._callback = callback
        # on zenoh's own thread: a Python callback is otherwise handed its samples through a
        # queue of up to 256 (zenoh-python's default), where an image flood piled up hundreds
        # of MB of them waiting for the GIL; ``callback`` only queues a sample, boundedly
        on_sample = zenoh.handlers.Callback(self._on_sample, None, indirect=False)
        if self.qos.durability == Durability.TRANSIENT_LOCAL:
            from zenoh import ext

            history = ext.HistoryConfig(detect_late_publishers=True, max_samples=self.qos.depth)
            self._sub = ext.declare_advanced_subscriber(
                session, self.key, on_sample, history=history, allowed_origin=REMOTE)
        else:
            self._sub = session.declare_subscriber(self.key, on_sample, allowed_origin=REMOTE)
        self._token = session.liveliness().declare_token(self.token_key)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        attachment = None
        if sample.attachment is not None:
            try:
                attachment = decode_attachment(sample.attachment.to_bytes())
            except ValueError as exc:
                log.debug("%s: bad attachment: %s", self.topic, exc)
        else:
            # rmw_zenoh itself drops such samples; we accept them and say so.
            log.debug("%s: sample without attachment", self.topic)
        try:
            self._callback(sample.payload.to_bytes(), attachment)
        except Exception:  # a bad message must not kill zenoh's callback thread
            log.exception("%s: callback failed", self.topic)

    def close(self) -> None:
        """Undeclare the token and the subscriber."""
        self._token.undeclare()
        self._sub.undeclare()


class Ros2Node:
    """A ROS 2 node identity on an open zenoh session (one NN token).

    Ids come from one counter, as in rmw_zenoh: the node takes the first, each publisher or
    subscription the next. ``name`` must be a valid ROS node name; ``namespace`` starts with /.
    """

    def __init__(
        self,
        session: zenoh.Session,
        name: str,
        *,
        namespace: str = "/",
        domain_id: int = 0,
        enclave: str = "/",
    ) -> None:
        self._session = session
        self._ids = EntityIds()
        self.info = NodeInfo(
            domain_id=domain_id,
            zid=str(session.info.zid()),
            node_id=self._ids.next(),
            name=validate_node_name(name),
            namespace=namespace,
            enclave=enclave,
        )
        self.token_key = node_token(self.info)
        self._token = session.liveliness().declare_token(self.token_key)
        self._entities: list[Ros2Publisher | Ros2Subscription] = []

    def create_publisher(
        self, topic: str, ros_type: str, type_hash: str, qos: Qos = QOS_DEFAULT_10
    ) -> Ros2Publisher:
        """Publisher on ``topic`` (relative names resolve against the node namespace)."""
        pub = Ros2Publisher(
            self._session,
            self.info,
            self._ids.next(),
            fully_qualified_name(topic, self.info.namespace),
            ros_type,
            type_hash,
            qos,
        )
        self._entities.append(pub)
        return pub

    def create_subscription(
        self,
        topic: str,
        ros_type: str,
        type_hash: str,
        callback: SampleCallback,
        qos: Qos = QOS_DEFAULT_10,
    ) -> Ros2Subscription:
        """Subscription on ``topic``; ``callback`` runs on zenoh's network thread (holding up
        everything else the session receives): it should only queue the sample."""
        sub = Ros2Subscription(
            self._session,
            self.info,
            self._ids.next(),
            fully_qualified_name(topic, self.info.namespace),
            ros_type,
            type_hash,
            qos,
            callback,
        )
        self._entities.append(sub)
        return sub

    def close(self) -> None:
        """Undeclare every entity, then the node token."""
        for entity in reversed(self._entities):
            entity.close()
        self._entities.clear()
        self._token.undeclare()
