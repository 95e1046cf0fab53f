"""Who may say what on gngdt's keys: one role per kind of service, each allowed to publish only
the streams DESIGN's topics table gives it, enforced by the router's zenoh access control.

- capture: puts ``gngdt/<cam>/{color,depth,calibration,points,tf,eos}``, token
  ``gngdt/<cam>/capture/alive``;
- learner: puts ``gngdt/<cam>/{topology,objects,scene,learner/status}`` and answers topology
  queries, tokens ``gngdt/<cam>/learner/alive`` and ``gngdt/<cam>/learner/instance/*``;
- logger: puts nothing, token ``gngdt/logger/alive/*``;
- viewer: puts nothing, no token.

Every role may subscribe to, query and hear the liveliness of ``gngdt/**``; nothing else is
allowed (``default_permission: deny``). `access_control` builds zenoh's ``access_control``
section for given subjects: usernames (``gngdt run``'s own router, one user and password per
role) or certificate common names (``config/secure/router.json5``, which a test keeps equal to
it).
"""

from __future__ import annotations

from typing import Any

from schemas.wire import CAPTURE_STREAMS, LEARNER_STREAMS

__all__ = ["ROLES", "ROLE_STREAMS", "ROLE_TOKENS", "SERVICE_ROLES", "access_control"]

#: the streams each role may put on, per camera (``gngdt/<cam>/<stream>``)
ROLE_STREAMS: dict[str, tuple[str, ...]] = {
    "capture": CAPTURE_STREAMS,
    "learner": LEARNER_STREAMS,
    "logger": (),
    "viewer": (),
}
#: the liveliness tokens each role may declare
ROLE_TOKENS: dict[str, tuple[str, ...]] = {
    "capture": ("gngdt/*/capture/alive",),
    "learner": ("gngdt/*/learner/alive", "gngdt/*/learner/instance/*"),
    "logger": ("gngdt/logger/alive/*",),
    "viewer": (),
}
ROLES = tuple(ROLE_STREAMS)
#: the role of each gngdt service (subcommand)
SERVICE_ROLES = {"capture": "capture", "learn": "learner", "log": "logger"}

_EVERYTHING = ["gngdt/**"]


def _rule(rule_id: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages,
            "key_exprs": keys}


def _role_rules(role: str) -> list[dict[str, Any]]:
    """What ``role`` may send in: its puts (the learner also answers topology queries) and its
    liveliness tokens."""
    rules = []
    streams = [f"gngdt/*/{stream}" for stream in ROLE_STREAMS[role]]
    if streams:
        messages = ["put"] + (["declare_queryable", "reply"] if role == "learner" else [])
        rules.append(_rule(f"{role} puts", "ingress", messages, streams))
    if ROLE_TOKENS[role]:
        rules.append(_rule(f"{role} tokens", "ingress", ["liveliness_token"],
                           list(ROLE_TOKENS[role])))
    return rules


def access_control(subjects: dict[str, dict[str, list[str]]]) -> dict[str, Any]:
    """zenoh's ``access_control`` section: ``subjects`` maps each role to its zenoh subject
    fields, e.g. ``{"capture": {"usernames": ["capture"]}}`` or ``{"cert_common_names":
    ["gngdt-capture"]}``; roles left out get no access at all."""
    shared = [
        # subscribe, query and hear liveliness: every role
        _rule("read", "ingress", ["declare_subscriber", "query",
                                  "declare_liveliness_subscriber", "liveliness_query"],
              _EVERYTHING),
        # what the router sends a role: samples, replies, queries for its queryables,
        # liveliness, and the declarations that tell a publisher someone listens
        _rule("receive", "egress", ["put", "delete", "reply", "query", "liveliness_token",
                                    "declare_subscriber", "declare_queryable"], _EVERYTHING),
    ]
    rules = list(shared)
    policies = []
    for role in subjects:
        own = _role_rules(role)
        rules += own
        policies.append({"rules": [rule["id"] for rule in shared + own], "subjects": [role]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": [{"id": role, **fields} for role, fields in subjects.items()],
        "policies": policies,
    }
