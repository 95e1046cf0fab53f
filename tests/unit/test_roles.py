"""One role per service (issue 24.2): the access control of `gngdt run`'s router and of
config/secure/router.json5 are the same rules, the run's credentials are private files, and a
secure router never listens where a client needs no credentials."""

from __future__ import annotations

import json
import stat
from pathlib import Path

import pytest

from gngdt.services.plumbing.roles import ROLE_STREAMS, ROLES, RunAccess, access_control
from gngdt.services.plumbing.session import ZenohSetupError, router_config

SECURE = Path(__file__).resolve().parents[2] / "config" / "secure"


def normalised(section: dict) -> dict:
    """An access_control section as zenoh reads it (defaults filled in)."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("access_control", json.dumps(section))
    return json.loads(config.get_json("access_control"))


def test_the_secure_router_grants_exactly_the_roles_of_gngdt_run() -> None:
    import zenoh

    shipped = json.loads(zenoh.Config.from_file(str(SECURE / "router.json5"))
                         .get_json("access_control"))
    by_certificate = {role: {"cert_common_names": [f"gngdt-{role}"]} for role in ROLES}
    assert shipped == normalised(access_control(by_certificate))


def test_each_role_may_put_only_its_own_streams() -> None:
    section = access_control({role: {"usernames": [role]} for role in ROLES})
    assert section["default_permission"] == "deny"
    puts = {policy["subjects"][0]: [rule for rule in section["rules"]
                                    if rule["id"] in policy["rules"]
                                    and "put" in rule["messages"]
                                    and rule["flows"] == ["ingress"]]
            for policy in section["policies"]}
    assert [rule["key_exprs"] for rule in puts["capture"]] == [[
        f"gngdt/*/{stream}" for stream in ("color", "depth", "calibration", "points", "tf",
                                           "eos")]]
    assert [rule["key_exprs"] for rule in puts["learner"]] == [[
        f"gngdt/*/{stream}" for stream in ROLE_STREAMS["learner"]]]
    assert puts["logger"] == puts["viewer"] == []


def test_the_client_files_differ_only_in_their_role() -> None:
    texts = {role: (SECURE / f"client-{role}.json5").read_text() for role in ROLES}
    for role, text in texts.items():
        assert text.replace(role, "ROLE") == texts["capture"].replace("capture", "ROLE")


def test_a_secure_router_never_listens_without_credentials() -> None:
    config = router_config(None, SECURE / "router.json5")  # the file's own endpoints
    assert json.loads(config.get_json("listen/endpoints")) == ["tls/127.0.0.1:7447"]
    with pytest.raises(ZenohSetupError, match=r"tcp/127\.0\.0\.1:7447 without credentials"):
        router_config(["tcp/127.0.0.1:7447"], SECURE / "router.json5")
    # gngdt's loopback default asks for no credentials: nothing to refuse
    router_config(["tcp/127.0.0.1:7447"])


def test_the_runs_credentials_are_private_files_removed_at_its_end(tmp_path: Path) -> None:
    folder = tmp_path / "run"
    folder.mkdir(mode=0o700)
    access = RunAccess("tcp/127.0.0.1:7447", folder)
    files = [access.users_file, *access.client_files.values()]
    assert sorted(access.client_files) == ["bridge", "capture", "learner", "logger"]
    for path in files:
        assert stat.S_IMODE(path.stat().st_mode) == 0o600
    users = dict(line.split(":", 1) for line in access.users_file.read_text().splitlines())
    for role, path in access.client_files.items():  # each service gets its own role only
        auth = json.loads(path.read_text())["transport"]["auth"]["usrpwd"]
        assert auth == {"user": role, "password": users[role]}
    assert len(set(users.values())) == 4
    access.forget()
    assert not any(path.exists() for path in files)
