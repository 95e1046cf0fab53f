"""Security: loopback-only defaults without scouting, the TLS + access-control deployment of
``config/secure/`` on loopback, and checkpoint/parameter files that are validated, never
unpickled or evaluated."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from gngdt.io.checkpoints import CheckpointError, load_checkpoint, save_checkpoint
from gngdt.services.plumbing.session import (
    DEFAULT_ENDPOINT,
    client_config,
    router_config,
)

REPO_ROOT = Path(__file__).resolve().parents[2]


def setting(config, key: str):
    return json.loads(config.get_json(key))


# ------------------------------------------------------------------------ secure defaults
def test_default_configs_listen_on_loopback_only_with_scouting_off() -> None:
    router = router_config([DEFAULT_ENDPOINT])
    assert setting(router, "listen/endpoints") == ["tcp/127.0.0.1:7447"]
    assert setting(router, "connect/endpoints") == []
    service = client_config()
    assert setting(service, "mode") == "client"
    assert setting(service, "listen/endpoints") == []
    for config in (router, service):
        assert setting(config, "scouting/multicast/enabled") is False
        assert setting(config, "scouting/gossip/enabled") is False


# --------------------------------------------------------------- files are data, not code
class _Exploit:
    """Unpickling this would create ``marker``: proof that something was unpickled."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_checkpoint_with_a_pickled_object_is_refused_without_unpickling(tmp_path: Path) -> None:
    marker = tmp_path / "unpickled"
    path = tmp_path / "evil.npz"
    save_checkpoint(path, {"weights": np.arange(4, dtype=np.float32)})
    with np.load(path, allow_pickle=False) as archive:
        arrays = {key: archive[key] for key in archive.files}
    exploit = np.empty(1, dtype=object)
    exploit[0] = _Exploit(marker)
    arrays["state/weights"] = exploit
    np.savez(path, **arrays)  # numpy pickles object arrays
    with pytest.raises(CheckpointError, match=r"evil\.npz"):
        load_checkpoint(path)
    assert not marker.exists()


def test_checkpoint_metadata_is_covered_by_the_digest(tmp_path: Path) -> None:
    path = tmp_path / "ckpt.npz"
    save_checkpoint(path, {"weights": np.arange(4, dtype=np.float32)},
                    {"counters": {"frames_used": 3}})
    with np.load(path, allow_pickle=False) as archive:
        arrays = {key: archive[key] for key in archive.files}
    metadata = json.loads(str(arrays["metadata"]))
    metadata["counters"]["frames_used"] = 10**12
    arrays["metadata"] = np.array(json.dumps(metadata))
    np.savez(path, **arrays)
    with pytest.raises(CheckpointError, match="does not match its sha256"):
        load_checkpoint(path)


def test_checkpoint_zip_bomb_is_refused_before_reading(tmp_path: Path, monkeypatch) -> None:
    import zipfile

    from gngdt.io import checkpoints as checkpoint

    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("state/weights.npy", b"\x00" * 5_000_000)  # compresses to ~5 kB
    monkeypatch.setattr(checkpoint, "MAX_CHECKPOINT_BYTES", 1_000_000)
    assert path.stat().st_size < 100_000
    with pytest.raises(CheckpointError, match="declares 5000"):
        load_checkpoint(path)


def test_params_values_are_type_checked_never_evaluated(tmp_path: Path) -> None:
    from gngdt.io.profiles import load_profile

    marker = tmp_path / "evaluated"
    params = tmp_path / "evil.toml"
    params.write_text(f'samples_per_frame = "__import__(\'pathlib\').Path(\'{marker}\').touch()"\n')
    with pytest.raises(ValueError, match=r"evil\.toml: learner option samples_per_frame must be "
                                         r"an integer"):
        load_profile(params)
    assert not marker.exists()
