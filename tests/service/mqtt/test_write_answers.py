"""Where a set's result and its verified value go (README "Writes over MQTT"), on a real
mosquitto: a response topic is used only when it is the publisher's own (``replies/{user}/``),
and the verified value goes to the value topic the polled values use."""

from __future__ import annotations

import json
from pathlib import Path

from tests.service.http.conftest import service
from tests.service.mqtt.broker import mosquitto
from tests.service.mqtt.test_writes import PREFIX, operator, sets_served

STATUS = f"{PREFIX}/line_fc/fan1/status"


async def test_a_response_topic_not_the_publishers_own_is_never_written_to(
    tmp_path: Path,
) -> None:
    """op1 names the drive's status topic (Home Assistant reads anything but "online" there
    as unavailable) and op2's replies as its response topics: the results go to the drive's
    result topic instead; op1's own reply topic is still answered."""
    with mosquitto(tmp_path / "broker") as broker:
        async with service(tmp_path) as svc:
            async with (
                sets_served(broker, svc),
                operator(broker, "op1") as op,
                operator(broker, "op2") as other,
            ):
                for request_id, response in (("s1", STATUS), ("s2", "replies/op2/pending")):
                    await op.set("op1", "3-41", {"value": 12.5, "request_id": request_id},
                                 response_topic=response, correlation=b"c")  # fmt: skip
                    result = json.loads((await op.result(request_id)).payload)
                    assert result["outcome"] == "ok", result
                await op.set("op1", "3-41", {"value": 13, "request_id": "own"},
                             response_topic="replies/op1/a", correlation=b"c")  # fmt: skip
                await op.result("own", "replies/op1/a")
            statuses = [m.payload for m in op.seen if m.topic.value == STATUS]
            assert all(p == b"online" for p in statuses), statuses
            assert not [m for m in other.seen if m.topic.value.startswith("replies/")]


async def test_a_set_with_index_0_in_its_topic_publishes_on_the_value_topic(tmp_path: Path) -> None:
    """3-41 is no array and is polled at one index: its value topic has no index (README
    "MQTT"), whether the set named index 0 or none."""
    with mosquitto(tmp_path / "broker") as broker:
        async with service(tmp_path) as svc:
            async with sets_served(broker, svc), operator(broker, "op1") as op:
                await op.set("op1", "3-41/0", {"value": 12.5, "request_id": "i0"})
                await op.result("i0")
                await op.set("op1", "3-41", {"value": 13, "request_id": "none"})
                await op.result("none")
                await op.first(lambda m: "/value/3-41" in m.topic.value
                               and json.loads(m.payload)["v"] == 13)  # fmt: skip
            shown = [m for m in op.seen if "/value/3-41" in m.topic.value]
            topics = {m.topic.value for m in shown}
            assert topics == {f"{PREFIX}/line_fc/fan1/value/3-41"}, topics
            verified = [json.loads(m.payload)["v"] for m in shown]
            assert 12.5 in verified and 13 in verified
