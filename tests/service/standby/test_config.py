"""The ``standby:`` section of the configuration file."""

from __future__ import annotations

import pytest

from pkwbus.service.config import ConfigError, parse_config

LINE = (
    "lines:\n- {name: l1, port: 'sim://fc?drives=1', protocol: fc, baudrate: 9600,"
    " drives: [{name: d1, address: 1}]}\n"
)


def problems(section: str) -> list[str]:
    with pytest.raises(ConfigError) as caught:
        parse_config(LINE + section)
    return caught.value.problems


@pytest.mark.parametrize("section", ["", "standby: off\n", "standby:\n", "standby: {}\n"])
def test_absent_or_off_is_one_instance(section: str) -> None:
    assert parse_config(LINE + section).standby is None


def test_the_section_as_the_interface_writes_it() -> None:
    config = parse_config(
        LINE + "standby:\n"
        '  etcd: ["http://etcd-0:2379", "http://etcd-1:2379", "https://etcd-2:2379/"]\n'
        "  lease: 6s\n  prefix: /site/hall-a\n  name: hall-a\n"
        "  advertise: http://10.0.0.5:9725\n"
    ).standby
    assert config is not None
    assert config.etcd == ["http://etcd-0:2379", "http://etcd-1:2379", "https://etcd-2:2379"]
    assert (config.lease, config.prefix, config.name) == (6.0, "/site/hall-a", "hall-a")
    assert config.advertise == "http://10.0.0.5:9725"


def test_the_name_comes_from_the_environment_else_the_host(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setenv("PKWBUS_INSTANCE", "pod-7")
    config = parse_config(LINE + "standby: {etcd: [http://e:2379], lease: 2s}\n").standby
    assert config is not None and config.name == "pod-7" and config.prefix == "/pkwbus"
    monkeypatch.delenv("PKWBUS_INSTANCE")
    monkeypatch.setattr("socket.gethostname", lambda: "node-3")
    config = parse_config(LINE + "standby: {etcd: [http://e:2379], lease: 60s}\n").standby
    assert config is not None and config.name == "node-3"


def test_instances_sharing_one_file_advertise_each_its_own_address(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """``{name}`` in ``advertise`` is the instance's name; ``PKWBUS_ADVERTISE`` gives the
    address where the file has none (the file's wins)."""
    section = "standby: {etcd: [http://e:2379], lease: 4s, advertise: 'http://{name}:9725'}\n"
    for name in ("pkwbus-a", "pkwbus-b"):
        monkeypatch.setenv("PKWBUS_INSTANCE", name)
        config = parse_config(LINE + section).standby
        assert config is not None and config.advertise == f"http://{name}:9725"
    monkeypatch.setenv("PKWBUS_INSTANCE", "pod-7")
    monkeypatch.setenv("PKWBUS_ADVERTISE", "http://{name}.pkwbus.plant:9725/")
    config = parse_config(LINE + "standby: {etcd: [http://e:2379], lease: 4s}\n").standby
    assert config is not None and config.advertise == "http://pod-7.pkwbus.plant:9725"
    config = parse_config(LINE + section).standby
    assert config is not None and config.advertise == "http://pod-7:9725"
    monkeypatch.setenv("PKWBUS_ADVERTISE", "somewhere")
    found = problems("standby: {etcd: [http://e:2379], lease: 4s}\n")
    assert found == [found[0]] and found[0].startswith("standby.advertise: 'somewhere' is not")


E = "standby: {etcd: [http://e:2379]"  # the start of a section; each case ends it


@pytest.mark.parametrize(
    ("section", "expected"),
    [
        (E + ", lease: 1s}", "standby.lease: '1s' is too short for a standby lease (2 s to 1 min)"),
        (E + ", lease: 61s}", "standby.lease: '61s' is too long"),
        (E + ", lease: soon}", "standby.lease: 'soon' is not a duration"),
        (E + "}", "standby.lease: is required"),
        ("standby: {lease: 6s}", "standby.etcd: is required"),
        ("standby: {etcd: [], lease: 6s}", "standby.etcd: must list etcd's client URLs"),
        ("standby: {etcd: [ftp://e:2379], lease: 6s}", "standby.etcd: 'ftp://e:2379' is not a"),
        ("standby: {etcd: [http://e], lease: 6s}", "standby.etcd: 'http://e' is not an etcd"),
        ("standby: {etcd: [http://e:1, http://e:1], lease: 6s}", "standby.etcd: names an endpoint"),
        (E + ", lease: 6s, prefix: pkwbus}", "standby.prefix: 'pkwbus' is not a key prefix"),
        (E + ", lease: 6s, prefix: /a/}", "standby.prefix: '/a/' is not a key prefix"),
        (E + ", lease: 6s, name: a/b}", "standby.name: 'a/b' is not an instance name"),
        (E + ", lease: 6s, advertise: here}", "standby.advertise: 'here' is not a URL"),
        (
            E + ", lease: 6s, advertise: 'http://{host}:9725'}",
            "standby.advertise: 'http://{host}:9725' is not an address to advertise: the one"
            " placeholder is {name}",
        ),
        (E + ", lease: 6s, advertise: 'http://{name:9725'}", "standby.advertise: 'http://{name:"),
        (E + ", lease: 6s, leases: 6s}", "standby.leases: is not a known setting"),
        ("standby: on", "standby: needs its settings"),
    ],
)
def test_a_bad_value_is_told_with_its_place(section: str, expected: str) -> None:
    found = problems(section + "\n")
    assert len(found) == 1 and found[0].startswith(expected), found
