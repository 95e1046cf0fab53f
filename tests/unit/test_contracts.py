"""docs/contracts.md is the contract: it names every stream, message and liveliness token the
code uses, and the code cites it (not the DESIGN.md it replaced)."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

from gngdt.schemas import gngdt_pb2, wire
from gngdt.schemas.wire import CAPTURE_STREAMS, LEARNER_STREAMS, alive_key, learner_instance_key

REPO = Path(__file__).resolve().parents[2]
CONTRACTS = (REPO / "docs" / "contracts.md").read_text()


def test_every_stream_and_message_is_in_the_contract() -> None:
    for stream in {*CAPTURE_STREAMS, *LEARNER_STREAMS}:
        assert f"`gngdt/<cam>/{stream}`" in CONTRACTS, stream
    payloads = [value.split(";")[1] for name, value in vars(wire).items()
                if name.startswith("ENCODING_")]
    assert "gngdt.FrameAck" in payloads
    for message in payloads:
        assert message in CONTRACTS, message
        if message.startswith("gngdt."):
            assert message.removeprefix("gngdt.") in gngdt_pb2.DESCRIPTOR.message_types_by_name
    for service in ("capture", "learner", "ros2"):
        assert f"`{alive_key('<cam>', service)}`" in CONTRACTS, service
    assert f"`{learner_instance_key('<cam>', '<zenoh id>')}`" in CONTRACTS


def test_the_code_cites_the_contract_not_its_origin() -> None:
    listed = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True,
                            check=True).stdout.split()
    citing = [name for name in listed if name.endswith((".py", ".md", ".proto"))
              and name not in ("CHANGELOG.md", "docs/contracts.md", "tests/unit/test_contracts.py")
              and re.search(r"DESIGN\.md", (REPO / name).read_text())]
    assert not citing, citing
