"""Who may say what on gngdt's keys: one role per kind of service, each allowed to publish only
the streams the contract's topics table gives it, enforced by the router's zenoh access control.

- capture: puts ``gngdt/<cam>/{color,depth,calibration,points,tf,eos}``, token
  ``gngdt/<cam>/capture/alive``;
- learner: puts ``gngdt/<cam>/{topology,objects,scene,learner/status}`` and answers topology
  queries, tokens ``gngdt/<cam>/learner/alive`` and ``gngdt/<cam>/learner/instance/*``;
- logger: puts nothing, token ``gngdt/logger/alive/*``;
- bridge (``gngdt ros2``): with camera input from ROS 2 puts that camera's
  ``gngdt/<cam>/{color,depth,calibration,points}``, tokens ``gngdt/<cam>/ros2/alive`` and
  ``gngdt/<cam>/capture/alive`` (``gngdt run --ros2`` starts it without input: it puts nothing);
- viewer: puts nothing, no token.

Every role may subscribe to, query and hear the liveliness of ``gngdt/**``; nothing else is
allowed (``default_permission: deny``). `access_control` builds zenoh's ``access_control``
section for given subjects: usernames (``gngdt run``'s own router, one user and password per
role: `RunAccess`) or certificate common names (``config/secure/router.json5``, which a test
keeps equal to it).
"""

from __future__ import annotations

import json
import logging
import os
import secrets
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from gngdt.schemas.wire import (
    ALL_KEYS,
    ANY_CAMERA,
    BRIDGE,
    CAPTURE,
    CAPTURE_STREAMS,
    LEARNER,
    LEARNER_STREAMS,
    alive_key,
    learner_instance_key,
    logger_alive_key,
    topic,
)
from gngdt.services.plumbing.session import client_settings, router_config, settings_file_text

if TYPE_CHECKING:
    import zenoh

__all__ = ["ROLES", "ROLE_STREAMS", "ROLE_TOKENS", "RUN_FOLDER_PREFIX", "SERVICE_ROLES",
           "RunAccess", "access_control", "remove_stale_credentials"]

log = logging.getLogger(__name__)

#: a ``gngdt run``'s private folder (``tempfile.mkdtemp(prefix=...)``)
RUN_FOLDER_PREFIX = "gngdt-run-"
#: the file in it naming the run's process: ``<pid> <start time>`` (the start time tells a
#: reused pid from the run's own)
OWNER_FILE = "run.pid"

#: the streams each role may put on, per camera (``gngdt/<cam>/<stream>``)
ROLE_STREAMS: dict[str, tuple[str, ...]] = {
    "capture": CAPTURE_STREAMS,
    "learner": LEARNER_STREAMS,
    "logger": (),
    "bridge": ("color", "depth", "calibration", "points"),
    "viewer": (),
}
#: the liveliness tokens each role may declare
ROLE_TOKENS: dict[str, tuple[str, ...]] = {
    "capture": (alive_key(ANY_CAMERA, CAPTURE),),
    "learner": (alive_key(ANY_CAMERA, LEARNER), learner_instance_key(ANY_CAMERA)),
    "logger": (logger_alive_key(),),
    "bridge": (alive_key(ANY_CAMERA, BRIDGE), alive_key(ANY_CAMERA, CAPTURE)),
    "viewer": (),
}
ROLES = tuple(ROLE_STREAMS)
#: the role of each gngdt service (subcommand)
SERVICE_ROLES = {"capture": "capture", "learn": "learner", "log": "logger", "ros2": "bridge"}

_EVERYTHING = [ALL_KEYS]


def _rule(rule_id: str, flow: str, messages: list[str], keys: list[str]) -> dict[str, Any]:
    return {"id": rule_id, "permission": "allow", "flows": [flow], "messages": messages,
            "key_exprs": keys}


def _role_rules(role: str) -> list[dict[str, Any]]:
    """What ``role`` may send in: its puts (the learner also answers topology queries) and its
    liveliness tokens."""
    rules = []
    streams = [topic(ANY_CAMERA, stream) for stream in ROLE_STREAMS[role]]
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


class RunAccess:
    """A ``gngdt run``'s zenoh credentials: one user and password per role, so that each
    service may put only on its own streams (a logger or a learner cannot end the stream, a
    capture cannot publish objects); the router's
    password file and each role's client configuration are written, mode 0600, into the run's
    private folder (0700, made by ``tempfile.mkdtemp``) and removed when the run ends.

    Other users can neither read them nor reach the router without them. A process of the same
    user can: it may read these files while the run lasts (or a service's memory, e.g. through
    ptrace) and then speak as that role on the run's router, e.g. end the stream with the
    capture's credentials; roles only keep each service, or whoever holds its credentials, to
    its own streams."""

    def __init__(self, endpoint: str, folder: Path) -> None:
        self.endpoint = endpoint
        passwords = {role: secrets.token_urlsafe(24) for role in SERVICE_ROLES.values()}
        self.owner_file = folder / OWNER_FILE
        write_private(self.owner_file, f"{os.getpid()} {process_start(os.getpid())}\n")
        self.users_file = folder / "router-users.txt"
        self.client_files = {role: folder / f"{role}.json5" for role in passwords}
        write_private(self.users_file,
                      "".join(f"{role}:{password}\n" for role, password in passwords.items()))
        for role, password in passwords.items():
            write_private(self.client_files[role],
                          settings_file_text(self._client_settings(role, password)))

    def client_file(self, service: str) -> Path:
        """The client configuration of a service (``learn``, ``log``, ``capture``)."""
        return self.client_files[SERVICE_ROLES[service]]

    def _client_settings(self, role: str, password: str) -> dict[str, Any]:
        """A role's zenoh configuration, by key path."""
        return {**client_settings([self.endpoint]),
                "transport/auth/usrpwd": {"user": role, "password": password}}

    def router(self) -> zenoh.Config:
        config = router_config([self.endpoint])
        config.insert_json5("transport/auth/usrpwd/dictionary_file",
                            json.dumps(str(self.users_file)))
        config.insert_json5("access_control", json.dumps(access_control(
            {role: {"usernames": [role]} for role in self.client_files})))
        return config

    def forget(self) -> None:
        """Remove the credentials (the logs stay, for a failed run)."""
        for path in credential_files(self.users_file.parent):
            path.unlink(missing_ok=True)


def credential_files(folder: Path) -> list[Path]:
    """The files a `RunAccess` writes into ``folder``."""
    return [folder / OWNER_FILE, folder / "router-users.txt",
            *(folder / f"{role}.json5" for role in SERVICE_ROLES.values())]


def _stat_fields(pid: int) -> list[str]:
    """The fields of /proc/<pid>/stat after the command's name ([] when unknown)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return []


def process_start(pid: int) -> str:
    """When process ``pid`` started (clock ticks since boot, /proc), "" when unknown."""
    fields = _stat_fields(pid)
    return fields[19] if len(fields) > 19 else ""


def _run_gone(owner_file: Path) -> bool:
    """Whether the run an owner file names has ended (its pid gone, or reused by another
    process: another start time)."""
    try:
        pid_text, _, started = owner_file.read_text().strip().partition(" ")
        pid = int(pid_text)
    except (OSError, ValueError):
        return False  # unreadable: not judged
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except PermissionError:  # a process of another user: not ours, so not our run
        return True
    fields = _stat_fields(pid)
    if fields[:1] in (["Z"], ["X"]):  # dead, not yet reaped (an orphan waits for init)
        return True
    return bool(started) and process_start(pid) not in ("", started)


def remove_stale_credentials(temp_dir: Path | None = None) -> list[Path]:
    """Remove the credentials that runs killed before they could (``kill -9``, a crash) left
    in their private folders under ``temp_dir`` (default the system's): a folder of this
    user's whose owner file names a process that has ended. The logs stay; an emptied folder
    goes. The folders cleaned."""
    temp_dir = Path(temp_dir or tempfile.gettempdir())
    cleaned = []
    for folder in temp_dir.glob(f"{RUN_FOLDER_PREFIX}*"):
        try:
            if not folder.is_dir() or folder.stat().st_uid != os.getuid():
                continue
        except OSError:
            continue
        if not _run_gone(folder / OWNER_FILE):
            continue
        for path in credential_files(folder):
            path.unlink(missing_ok=True)
        try:
            folder.rmdir()  # only when nothing else (a failed run's logs) is left
        except OSError:
            pass
        cleaned.append(folder)
        log.info("removed the credentials of a run that ended without removing them: %s",
                 folder)
    return cleaned


def write_private(path: Path, text: str) -> None:
    """Write a new file only its owner may read (0600)."""
    descriptor = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(descriptor, "w") as file:
        file.write(text)
