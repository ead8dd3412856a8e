"""udp:// address parsing, and the mission file reference (missions/README.md) staying true."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
import yaml

from mexgen_gcs.config import UdpAddress, load_mission, parse_mission, parse_udp_url
from mexgen_gcs.config.describe import schema_reference

REPO = Path(__file__).resolve().parents[2]
README = (REPO / "missions" / "README.md").read_text(encoding="utf-8")


@pytest.mark.parametrize(("url", "host", "port"), [
    ("udp://0.0.0.0:14600", "0.0.0.0", 14600),
    ("udp://127.0.0.1:0", "127.0.0.1", 0),
    ("udp://[::1]:14600", "::1", 14600),
    ("udp://localhost:65535", "localhost", 65535),
    ("udp://radio.local:9", "radio.local", 9),
])
def test_parse_udp_url(url: str, host: str, port: int) -> None:
    address = parse_udp_url(url)
    assert address == UdpAddress(host, port)
    assert parse_udp_url(address.url()) == address


@pytest.mark.parametrize("url", [
    "udp://0.0.0.0", "tcp://0.0.0.0:1", "0.0.0.0:14600", "udp://:14600", "udp://h:port",
    "udp://h:70000", "udp://::1:5", "udp://[zz]:5", "udp://[::1]5", "udp://bad_host!:5",
    "udp://h:-1", "",
])
def test_parse_udp_url_rejects(url: str) -> None:
    with pytest.raises(ValueError, match="expected udp://HOST:PORT"):
        parse_udp_url(url)


def test_readme_documents_every_key() -> None:
    keys = [doc.key for doc in schema_reference()]
    assert len(keys) > 100
    missing = [k for k in keys if f"`{k}`" not in README]
    assert missing == []


def test_every_key_has_a_description() -> None:
    assert [d.key for d in schema_reference() if not d.description] == []


def test_readme_yaml_examples_load(tmp_path: Path) -> None:
    blocks = re.findall(r"```yaml\n(.*?)```", README, flags=re.S)
    assert len(blocks) == 2
    minimal = parse_mission(blocks[0], "README minimal")
    assert minimal.name == "minimal"
    faults = yaml.safe_load(blocks[1])["sim"]["faults"]
    demo = (REPO / "missions" / "demo.yaml").read_text(encoding="utf-8")
    with_faults = demo.replace("  faults: []", "  faults: " + yaml.safe_dump(faults,
                                                                             default_flow_style=True))
    path = tmp_path / "faults.yaml"
    path.write_text(with_faults, encoding="utf-8")
    mission = load_mission(path)
    assert [f.kind for f in mission.sim.faults] == [
        "link_drop", "gps_loss", "battery_sag", "radio_silence", "detection_dropout", "clutter",
        "clock_offset", "clock_drift"]
