"""The ``mqtt:`` section as the file gives it, and the outbox's caps and order (a fake
clock): what is acknowledged goes, what is over max_bytes or max_age is dropped oldest
first and counted, and what an earlier run left is there after a reopen."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from pkwbus.service.config import ConfigError, parse_config
from pkwbus.service.config.mqtt import (
    EXTRA_HINT,
    Mqtt,
    MqttSettingsError,
    ha_device_id,
    mqtt_report,
)
from pkwbus.service.mqtt.outbox import Outbox

LINES = """
lines:
  - name: l1
    port: sim://fc?drives=1
    protocol: fc
    baudrate: 115200
    drives:
      - {name: a, address: 1, catalog: danfoss-fc, poll: [{parameter: "16-13", every: 1s}]}
"""


def config(mqtt: str) -> Mqtt:
    found = parse_config(f"mqtt:\n{mqtt}\n{LINES}", environ={}).mqtt
    assert found is not None
    return found


def problems(mqtt: str) -> list[str]:
    with pytest.raises(ConfigError) as exc:
        parse_config(f"mqtt:\n{mqtt}\n{LINES}", environ={})
    return exc.value.problems


def test_the_defaults_and_the_written_forms() -> None:
    found = config(
        "  url: mqtts://broker.plant:8884\n  writes: off\n"
        "  outbox: {max_bytes: 1MiB, max_age: 2h}\n  values: {heartbeat: 30s}"
    )
    assert (found.host, found.port, found.tls) == ("broker.plant", 8884, True)
    assert found.writes == "off" and found.prefix == "pkwbus"
    assert found.outbox.max_bytes == 1024**2 and found.outbox.max_age == 7200.0
    assert found.values.heartbeat == 30.0 and found.values.deadband == 0.0
    assert found.homeassistant.discovery and found.homeassistant.prefix == "homeassistant"
    assert config("  url: mqtt://10.0.0.5").port == 1883


@pytest.mark.parametrize(
    ("given", "said"),
    [
        ("  url: http://broker:1883", "mqtt.url"),
        ("  url: mqtt://user:pw@broker", "username_env"),
        ("  url: mqtt://broker:0", "port"),
        ("  url: mqtt://broker\n  prefix: pkwbus/+/x", "mqtt.prefix"),
        ("  url: mqtt://broker\n  writes: yes please", "mqtt.writes"),
        ("  url: mqtt://broker\n  values: {heartbeat: 0.1s}", "mqtt.values.heartbeat"),
        ("  url: mqtt://broker\n  outbox: {max_bytes: 12 apples}", "mqtt.outbox.max_bytes"),
        ("  url: mqtt://broker\n  username_env: 1BAD", "mqtt.username_env"),
    ],
)
def test_a_bad_section_is_refused_at_its_place(given: str, said: str) -> None:
    assert any(said in p for p in problems(given)), problems(given)


def test_the_account_comes_from_the_environment() -> None:
    found = config("  url: mqtt://broker\n  username_env: U\n  password_env: P")
    assert found.credentials({"U": "svc", "P": "pw"}) == ("svc", "pw")
    with pytest.raises(MqttSettingsError, match="P is not set"):
        found.credentials({"U": "svc"})
    assert config("  url: mqtt://broker").credentials({}) == (None, None)


def test_without_the_extra_the_section_names_the_install(monkeypatch: pytest.MonkeyPatch) -> None:
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "aiomqtt" else real(name, *a)
    )
    assert any(EXTRA_HINT in p for p in problems("  url: mqtt://broker"))


def test_check_config_says_the_rates() -> None:
    found = config("  url: mqtt://broker\n  values: {heartbeat: 10s}")
    said = list(mqtt_report(found, [1.0, 4.0], 2))
    assert "2 value(s) of 2 drive(s), 0.20 to 5.0 messages/s" in said[0]
    assert "2 Home Assistant device config(s)" in said[1]


class Clock:
    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def test_the_outbox_keeps_order_until_acknowledged_and_over_restarts(tmp_path: Path) -> None:
    clock = Clock()
    box = Outbox(tmp_path / "o.sqlite", 10_000, 3600.0, clock)
    assert box.add([("t/a", b"1"), ("t/b", b"22")]) == 0
    rows, dropped = box.oldest(10)
    assert [(r.topic, r.payload) for r in rows] == [("t/a", b"1"), ("t/b", b"22")]
    assert dropped == 0 and box.size() == (2, 3)
    box.delete([rows[0].id])
    box.close()
    again = Outbox(tmp_path / "o.sqlite", 10_000, 3600.0, clock)
    assert [r.payload for r in again.oldest(10)[0]] == [b"22"]
    assert again.size() == (1, 2)
    again.close()


def test_the_outbox_drops_the_oldest_over_its_caps(tmp_path: Path) -> None:
    clock = Clock()
    box = Outbox(tmp_path / "o.sqlite", 100, 60.0, clock)
    assert box.add([(f"t/{i}", b"x" * 30) for i in range(3)]) == 0  # 90 bytes
    assert box.add([("t/3", b"y" * 30)]) == 1  # 120 > 100: the oldest goes
    assert [r.topic for r in box.oldest(10)[0]] == ["t/1", "t/2", "t/3"]
    clock.now += 61.0
    box.add([("t/4", b"z")])
    rows, dropped = box.oldest(10)
    assert dropped == 0  # already dropped by the add
    assert [r.topic for r in rows] == ["t/4"] and box.size() == (1, 1)
    box.close()


TWO_FANS = """
lines:
  - name: l1
    port: sim://fc?drives=1,2
    protocol: fc
    baudrate: 115200
    drives:
      - {name: fan.1, address: 1, catalog: danfoss-fc}
      - {name: fan_1, address: 2, catalog: danfoss-fc}
"""


def test_drives_whose_home_assistant_ids_would_be_one_are_refused_while_discovery_is_on() -> None:
    with pytest.raises(ConfigError) as exc:
        parse_config(f"mqtt:\n  url: mqtt://broker\n{TWO_FANS}", environ={})
    (said,) = exc.value.problems
    assert said.startswith("lines[0].drives[1].name: 'fan_1'") and "pkwbus_l1_fan_1" in said
    off = "mqtt:\n  url: mqtt://broker\n  homeassistant: {discovery: false}\n"
    assert parse_config(off + TWO_FANS, environ={}).mqtt is not None


def test_a_site_in_the_prefix_is_in_the_device_id_and_the_default_id_stays() -> None:
    assert ha_device_id("pkwbus", "line_fc", "fan1") == "pkwbus_line_fc_fan1"
    assert ha_device_id("pkwbus/hall-a", "line_fc", "fan1") == "pkwbus_hall-a_line_fc_fan1"
    site = "pkwbus/hall-a"
    assert ha_device_id(site, "l", "fan.1") == ha_device_id(site, "l", "fan_1")
