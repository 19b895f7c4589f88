"""The drives' own logs on a PROFIBUS DP line: the SINAMICS fault buffer (whose r0944 and
r0947-r0949 are the PROFIdrive fault buffer's P944 and P947-P949) and alarm buffer read
through the PPO's PKW words of one slave and through data record 47 (DP-V1, PPO 3) of
another, as on a serial line: a trip and an alarm logged before pkwbus started are found
with the drive's runtime time."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from pkwbus.sim import ModelConfig, SimTiming
from pkwbus.sim.profibus.line import DpSimulator
from tests.service.history.test_service_logs import counted, kept, until, watching

STEADY = ModelConfig(warning_rate=0.0, trip_rate=0.0)  # only the trips the test makes


def dp_line(name: str, url: str, drive: str, address: int, access: str) -> str:
    """A DP line of one SINAMICS slave (``access``: its PPO and DP-V1 keys)."""
    return f"""
  - name: {name}
    port: "{url}"
    protocol: profibus
    baudrate: 93750
    slot_time: 50ms
    watchdog: 2s
    events_every: 1s
    drives:
      - {{name: {drive}, address: {address}, dialect: profidrive, ident: 0x80B5, {access},
         catalog: siemens-g120, poll: [{{parameter: r0021, every: 200ms}}]}}"""


def config_text(ppo_url: str, record_url: str, folder: Path) -> str:
    """The mixer's parameters through its PPO's PKW words, the pump's through data
    record 47 (PPO 3 has none)."""
    return (
        f"audit_db: {folder}/audit.sqlite\nlines:"
        + dp_line("dp1", ppo_url, "mixer", 8, "ppo: 1")
        + dp_line("dp2", record_url, "pump", 9, "ppo: 3, dpv1: true")
        + "\n"
    )


async def test_a_trip_before_the_start_is_found_through_the_ppo_and_data_record_47(
    tmp_path: Path,
) -> None:
    timing = SimTiming(response_delay=0.001)
    ppo = DpSimulator([8], timing=timing, model=STEADY)
    record = DpSimulator([9], timing=timing, model=STEADY, ppo_number=3, dpv1=True)
    ppo_end = await ppo.serve_tcp("127.0.0.1", 0)
    record_end = await record.serve_tcp("127.0.0.1", 0)
    try:
        tripped_at = time.time()
        ppo.drives[8].trip(7801, ppo.clock(), value=-12)
        record.drives[9].trip(30001, record.clock(), value=5)
        record.drives[9].warn(9, record.clock())  # A30030 comes, and stays
        async with watching(config_text(ppo_end.url, record_end.url, tmp_path)) as w:
            assert {(x.drive, x.log.name) for x in w.watched} == {
                (drive, log)
                for drive in ("mixer", "pump")
                for log in ("SINAMICS fault buffer", "SINAMICS alarm buffer")
            }
            await until(lambda: bool(kept(w, "mixer")) and len(kept(w, "pump")) == 2, 60)
            (mixer,) = kept(w, "mixer")
            pump = next(e for e in kept(w, "pump") if e.kind == "fault")
            (alarm,) = (e for e in kept(w, "pump") if e.kind == "alarm")
            assert (mixer.code, mixer.number, mixer.value) == ("F07801", 7801, -12)
            assert (pump.code, pump.number, pump.value) == ("F30001", 30001, 5)
            assert (alarm.code, alarm.number) == ("A30030", 30030)
            assert alarm.text == "Power unit: Internal overtemperature alarm"
            for entry in (mixer, pump, alarm):
                assert entry.time_source == "runtime" and entry.time is not None
                assert entry.time == pytest.approx(tripped_at, abs=1.0)
            await until(lambda: counted(w) == 3)  # each counted as it was stored
    finally:
        await ppo_end.close()
        await record_end.close()
