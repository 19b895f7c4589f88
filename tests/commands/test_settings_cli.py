"""`pkwbus backup` and `pkwbus restore` against simulated drives on TCP (socket://), served
from a thread of this process so that the drives' stored values and EEPROM can be read
at the simulator."""

from __future__ import annotations

import asyncio
import json
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml

from pkwbus.catalog import DEFAULT_CATALOGS, load_catalog
from pkwbus.cli import main
from pkwbus.protocol.buses import Bus
from pkwbus.protocol.errors import RemoteProtocolError
from pkwbus.protocol.pkw import PkwRequest
from pkwbus.protocol.pkw.dialects import WRITE_COMMANDS
from pkwbus.protocol.values import ValueType, danfoss_name, encode_value, siemens_name
from pkwbus.service.history.backup import Backup
from pkwbus.sim import ParamSpec, SimDrive, SimTiming, Simulator
from pkwbus.sim.drives.catalogs import specs_from_catalog
from tests.commands.test_dp_cli import dp
from tests.commands.test_dp_cli import serve as serve_dp

A, B = 1, 2  # a drive whose settings were changed at its keypad, and a factory one

# Settings set at A's keypad (writable, and changeable while the motor runs): raw numbers.
KEYPAD_FC = {341: 1250, 342: 800, 412: 100, 414: 450, 303: 1500}


class Served:
    """A simulator on TCP, served by an event loop in a thread of its own."""

    def __init__(self, sim: Simulator) -> None:
        self.sim = sim
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.server: Any = self._call(sim.serve_tcp("127.0.0.1", 0))
        self.url: str = self.server.url

    def _call(self, coro: Any) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(10)

    def drive(self, address: int) -> SimDrive:
        return self.sim.drives[address]

    def close(self) -> None:
        self._call(self.server.close())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)


def fc_simulator() -> Simulator:
    """FC drives of the default catalog, with 0-10 Active Set-up too."""
    setup = ParamSpec(10, "Active Set-up", ValueType.U16, writable=True, maximum=9, initial=1)
    specs = (*specs_from_catalog(Bus.FC, DEFAULT_CATALOGS["fc"]), setup)
    return Simulator("fc", [A, B], specs=specs, timing=SimTiming(response_delay=0.0))


@pytest.fixture
def fc() -> Iterator[Served]:
    served = Served(fc_simulator())
    yield served
    served.close()


@pytest.fixture
def uss() -> Iterator[Served]:
    sim = Simulator(
        "uss", [A, B], catalog=DEFAULT_CATALOGS["uss"], timing=SimTiming(response_delay=0.0)
    )
    served = Served(sim)
    yield served
    served.close()


def run(capsys: pytest.CaptureFixture[str], *args: str) -> tuple[int, str, str]:
    code = main(list(args))
    out = capsys.readouterr()
    return code, out.out, out.err


def line(served: Served, address: int, protocol: str = "fc") -> list[str]:
    return ["--port", served.url, "--protocol", protocol, "--address", str(address)]


def settings_of(catalog: str) -> list[tuple[int, int]]:
    """(PNU, index) of each setting of ``catalog``, in its order."""
    found: list[tuple[int, int]] = []
    for spec in load_catalog(catalog).parameters.values():
        if spec.is_setting:
            found.extend((spec.pnu, i) for i in (range(spec.array) if spec.array else [0]))
    return found


def changed_at_keypad(served: Served) -> None:
    for pnu, raw in KEYPAD_FC.items():
        served.sim.keypad(A, pnu, raw)


def back_up(
    capsys: pytest.CaptureFixture[str], served: Served, path: Path, protocol: str = "fc"
) -> dict[str, Any]:
    code, _, err = run(capsys, "backup", *line(served, A, protocol), "-o", str(path))
    assert code == 0, err
    text = path.read_text(encoding="utf-8")
    return dict(yaml.safe_load(text) if path.suffix == ".yaml" else json.loads(text))


def stored(drive: SimDrive) -> dict[tuple[int, int], int]:
    return dict(drive.params.raw)


# ------------------------------------------------------------------ backup


def test_backup_holds_every_catalog_setting_as_the_drive_does(
    capsys: pytest.CaptureFixture[str], fc: Served
) -> None:
    changed_at_keypad(fc)
    a = fc.drive(A)
    a.set_value(10, 2)  # 0-10 Active Set-up: set-up 2
    code, out, err = run(capsys, "backup", *line(fc, A), "--name", "press-4")
    assert code == 0, err
    document = json.loads(out)
    Backup.model_validate(document)  # the service's document
    assert document["drive"] == "press-4" and document["line"] == ""
    assert document["dialect"] == "fc" and document["catalog"] == "danfoss-fc"
    fc_type, software = (a.text(p).decode("latin-1").strip("\x00 ") for p in (1540, 1543))
    assert document["identity"] == f"fc:{fc_type}|{software}"
    assert document["setup"] == a.value(10) == 2
    assert document["time"].endswith("Z")
    wanted = settings_of("danfoss-fc")
    assert [(danfoss_name(p), i) for p, i in wanted] == [
        (s["parameter"], s["index"]) for s in document["settings"]
    ]
    for (pnu, index), row in zip(wanted, document["settings"], strict=True):
        assert row["raw"] == a.value(pnu, index), row
        assert row["value"] == pytest.approx(a.params.number(pnu, index)), row
        assert row["seen"].endswith("Z")
    ramp = next(s for s in document["settings"] if s["parameter"] == "3-41")
    assert ramp == {**ramp, "name": "Ramp 1 Ramp Up Time", "unit": "s", "value": 12.5}


def test_backup_without_the_setup_parameter_and_in_yaml(
    capsys: pytest.CaptureFixture[str], uss: Served, tmp_path: Path
) -> None:
    document = back_up(capsys, uss, tmp_path / "g120.yaml", "uss")
    assert document["setup"] is None  # no 0-10 on a Siemens drive
    a = uss.drive(A)
    wanted = settings_of("siemens-g120")
    assert [siemens_name("p", p) for p, _ in wanted] == [
        s["parameter"] for s in document["settings"]
    ]
    for (pnu, index), row in zip(wanted, document["settings"], strict=True):
        assert row["raw"] == a.value(pnu, index)


# ------------------------------------------------------------------ restore


def test_restore_makes_a_factory_drive_equal_to_the_backed_up_one(
    capsys: pytest.CaptureFixture[str], fc: Served, tmp_path: Path
) -> None:
    changed_at_keypad(fc)
    a, b = fc.drive(A), fc.drive(B)
    assert all(b.value(p) != a.value(p) for p in KEYPAD_FC)  # B differs before
    path = tmp_path / "a.yaml"
    back_up(capsys, fc, path)
    code, out, err = run(capsys, "restore", str(path), *line(fc, B), "--json")
    assert code == 0, err
    done = json.loads(out)
    planned = {(r["parameter"], r["index"]) for r in done["plan"]}
    assert planned == {(danfoss_name(p), 0) for p in KEYPAD_FC}
    assert [r["outcome"] for r in done["results"]] == ["ok"] * len(planned)
    for pnu, index in settings_of("danfoss-fc"):
        assert b.value(pnu, index) == a.value(pnu, index), danfoss_name(pnu)
    for pnu in KEYPAD_FC:  # each written with an EEPROM write request
        assert b.eeprom[pnu, 0] == a.value(pnu)
    skipped = {s["parameter"]: s["why"] for s in done["skipped"]}
    assert skipped["0-01"] == "read-only"  # the drive says: read-only over the bus


def test_dry_run_writes_nothing(
    capsys: pytest.CaptureFixture[str], fc: Served, tmp_path: Path
) -> None:
    changed_at_keypad(fc)
    path = tmp_path / "a.json"
    back_up(capsys, fc, path)
    b = fc.drive(B)
    before, eeprom = stored(b), dict(b.eeprom)
    code, out, err = run(capsys, "restore", str(path), *line(fc, B), "--dry-run")
    assert code == 0, err
    assert f"plan: {len(KEYPAD_FC)} write(s)" in out
    assert "3-41: 5 s -> 12.5 s" in out and "dry run: nothing written" in out
    assert stored(b) == before and dict(b.eeprom) == eeprom


def test_store_ram_writes_no_eeprom(
    capsys: pytest.CaptureFixture[str], fc: Served, tmp_path: Path
) -> None:
    changed_at_keypad(fc)
    path = tmp_path / "a.json"
    back_up(capsys, fc, path)
    b = fc.drive(B)
    code, _, err = run(capsys, "restore", str(path), *line(fc, B), "--store", "ram")
    assert code == 0, err
    assert b.value(341) == fc.drive(A).value(341) and (341, 0) not in b.eeprom


def test_a_refused_write_is_reported_and_the_restore_goes_on(
    capsys: pytest.CaptureFixture[str], fc: Served, tmp_path: Path
) -> None:
    changed_at_keypad(fc)
    a, b = fc.drive(A), fc.drive(B)
    a.set_value(120, a.value(120) + 100)  # 1-20 Motor Power: only while the motor stands
    assert b.running
    path = tmp_path / "a.json"
    back_up(capsys, fc, path)
    code, out, err = run(capsys, "restore", str(path), *line(fc, B), "--json")
    assert code == 1, err
    assert err == "pkwbus: 1 write(s) not made: 1-20 (rejected)\n"
    results = {r["parameter"]: r for r in json.loads(out)["results"]}
    refused = results.pop("1-20")
    assert refused["outcome"] == "rejected" and refused["fault"] == 17
    assert "can only be changed when the motor is turned off" in refused["detail"]
    assert refused["when_stopped"] is True
    assert {r["outcome"] for r in results.values()} == {"ok"}  # 1-20 came first
    assert b.value(120) != a.value(120)
    assert all(b.value(p) == a.value(p) for p in KEYPAD_FC)


def test_a_read_back_with_another_value_stops_the_restore(
    capsys: pytest.CaptureFixture[str],
    fc: Served,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    changed_at_keypad(fc)
    path = tmp_path / "a.json"
    back_up(capsys, fc, path)
    b = fc.drive(B)
    execute = b.params.execute

    def reverting(request: PkwRequest) -> Any:  # takes 3-41, then holds the old value again
        old = b.params.raw[341, 0]
        answer = execute(request)
        if request.pnu == 341 and request.command in WRITE_COMMANDS:
            b.params.raw[341, 0] = old
        return answer

    monkeypatch.setattr(b.params, "execute", reverting)
    code, out, err = run(capsys, "restore", str(path), *line(fc, B))
    assert code == 5, err
    assert err.startswith("pkwbus: the restore stopped at 3-41 (mismatch: read back 5 s")
    assert err.count("\n") == 1
    assert "3-42: not sent: the restore stopped at 3-41: mismatch" in out
    assert b.value(303) == fc.drive(A).value(303)  # 3-03 came before 3-41
    assert b.value(342) != fc.drive(A).value(342) and b.value(414) != fc.drive(A).value(414)


def test_a_write_without_an_answer_stops_the_restore(
    capsys: pytest.CaptureFixture[str],
    fc: Served,
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    changed_at_keypad(fc)
    path = tmp_path / "a.json"
    back_up(capsys, fc, path)
    b = fc.drive(B)
    execute = b.params.execute

    def dying(request: PkwRequest) -> Any:  # the drive goes silent at the write of 3-41
        if request.pnu == 341 and request.command in WRITE_COMMANDS:
            fc.sim.kill(B)
            raise RemoteProtocolError("gone")
        return execute(request)

    monkeypatch.setattr(b.params, "execute", dying)
    quick = ["--timeout", "50ms", "--retries", "1", "--deadline", "300ms"]
    code, out, err = run(capsys, "restore", str(path), *line(fc, B), *quick, "--json")
    assert code == 3, err
    results = {r["parameter"]: r for r in json.loads(out)["results"]}
    assert results["3-03"]["outcome"] == "ok" and results["3-41"]["outcome"] == "timeout"
    assert {results[p]["outcome"] for p in ("3-42", "4-12", "4-14")} == {"not_sent"}


def test_a_backup_of_another_drive_type_needs_force(
    capsys: pytest.CaptureFixture[str], fc: Served, tmp_path: Path
) -> None:
    changed_at_keypad(fc)
    document = back_up(capsys, fc, tmp_path / "a.json")
    document["identity"] = "fc:FC-302P7K5T5E20H1|06.02"  # another model
    path = tmp_path / "fc302.json"
    path.write_text(json.dumps(document), encoding="utf-8")
    b = fc.drive(B)
    before = stored(b)
    code, out, err = run(capsys, "restore", str(path), *line(fc, B))
    assert code == 2, err
    assert "another drive type (fc:FC-302P7K5T5E20H1, this drive is fc:FC-102)" in err
    assert f"skipped: all {len(document['settings'])}" in out
    assert stored(b) == before
    code, _, err = run(capsys, "restore", str(path), *line(fc, B), "--force")
    assert code == 0, err
    assert all(b.value(p) == fc.drive(A).value(p) for p in KEYPAD_FC)


def test_restore_of_a_siemens_drive(
    capsys: pytest.CaptureFixture[str], uss: Served, tmp_path: Path
) -> None:
    a, b = uss.drive(A), uss.drive(B)
    ramp = encode_value(12.5, ValueType.F32, a.params.specs[1120].scaling)
    uss.sim.keypad(A, 1120, ramp)
    path = tmp_path / "a.json"
    back_up(capsys, uss, path, "uss")
    assert b.value(1120) != ramp
    code, out, err = run(capsys, "restore", str(path), *line(uss, B, "uss"))
    assert code == 0, err
    assert "p1120: 10.0 s -> 12.5 s" in out
    assert b.value(1120) == ramp and b.eeprom[1120, 0] == ramp
    for pnu, index in settings_of("siemens-g120"):
        assert b.value(pnu, index) == a.value(pnu, index)


def test_a_dry_run_checks_each_write_as_it_would_go_out(
    capsys: pytest.CaptureFixture[str], uss: Served, tmp_path: Path
) -> None:
    """A value the parameter's type cannot hold exactly (p1120 is an f32) is not sent by a
    restore: its dry run says so and exits 2 (nothing sent, bad input), not 0."""
    path = tmp_path / "a.json"
    back_up(capsys, uss, path, "uss")
    document = json.loads(path.read_text())
    (ramp,) = [s for s in document["settings"] if s["parameter"] == "p1120"]
    ramp["value"] = 12.345678901234567
    path.write_text(json.dumps(document))
    b = uss.drive(B)
    before = stored(b)
    code, out, err = run(capsys, "restore", str(path), *line(uss, B, "uss"), "--dry-run")
    assert code == 2, (out, err)
    assert "p1120: invalid: not sent:" in out and "dry run: nothing written" in out
    assert "p1120 (invalid)" in err
    assert stored(b) == before
    code, out, _ = run(capsys, "restore", str(path), *line(uss, B, "uss"), "--dry-run",
                       "--json")  # fmt: skip
    results = json.loads(out)["results"]
    assert {r["parameter"]: r["outcome"] for r in results}["p1120"] == "invalid"
    assert {r["outcome"] for r in results if r["parameter"] != "p1120"} <= {"dry_run"}


@pytest.mark.parametrize(
    ("name", "text", "says"),
    [
        ("a.json", '{"pkwbus_backup": 1, "drive": "d", "settings": [', "not JSON"),
        ("a.json", "[1, 2]", "the document: Input should be"),
        ("a.json", '{"pkwbus_backup": 1, "settings": []}', "drive: Field required"),
        ("a.json", '{"pkwbus_backup": 2, "drive": "d"}', "pkwbus_backup: Input should be 1"),
        ("a.json", '{"drive": "d", "settings": [{"parameter": "3-41", "value": NaN}]}', "NaN"),
        ("a.yaml", "drive: d\nsettings: [\n", "line 3"),
        ("a.yaml", "drive: d\nsettings:\n  - parameter: 3-41\n    colour: red\n", "colour"),
    ],
)
def test_a_malformed_backup_is_one_line_and_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, name: str, text: str, says: str
) -> None:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    # The port does not exist: exit 2, not 4, shows nothing was opened or sent.
    code, out, err = run(
        capsys, "restore", str(path), "--port", "/nonexistent/tty", "--address", "1"
    )
    assert code == 2, err
    assert err.startswith(f"pkwbus: {path}: not a backup document: ") and err.count("\n") == 1
    assert says in err and out == ""


def test_a_missing_backup_file_is_exit_2(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    missing = tmp_path / "none.json"
    code, _, err = run(
        capsys, "restore", str(missing), "--port", "/nonexistent/tty", "--address", "1"
    )
    assert code == 2 and err == f"pkwbus: cannot read {missing}: No such file or directory\n"


def test_backup_to_a_folder_that_is_not_there_sends_nothing(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    target = tmp_path / "no" / "a.json"
    code, _, err = run(
        capsys, "backup", "--port", "/nonexistent/tty", "--address", "1", "-o", str(target)
    )
    assert code == 2 and "cannot write" in err and not target.exists()


def test_backup_and_restore_over_profibus_dp(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    served = serve_dp("tcp")
    try:
        a, b = served.sim.drives[8], served.sim.drives[9]
        a.set_value(341, 1250)
        path = tmp_path / "dp.json"
        code, _, err = run(capsys, "backup", *dp(served, "--address", "8", "-o", str(path)))
        assert code == 0, err
        rows = {s["parameter"]: s for s in json.loads(path.read_text())["settings"]}
        assert rows["3-41"]["raw"] == 1250 and rows["3-41"]["value"] == 12.5
        restore = ["restore", str(path), *dp(served, "--address", "9")]
        code, _, err = run(capsys, *restore)  # this dialect writes no EEPROM: not sent
        assert code == 1 and "3-41 (invalid)" in err and b.value(341) != 1250
        code, _, err = run(capsys, *restore, "--store", "ram")
        assert code == 0, err
        assert b.value(341) == 1250
    finally:
        served.close()
