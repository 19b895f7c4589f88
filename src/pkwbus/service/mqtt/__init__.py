"""MQTT for the plant's broker (README, "MQTT"): the connection (:mod:`.connection`), the
output of values, statuses, drive events and Home Assistant discovery (:mod:`.output`,
:mod:`.values`, :mod:`.discovery`), the outbox of what the broker has not acknowledged
(:mod:`.outbox`) and the output's series (:mod:`.metrics`). Needs the ``mqtt`` extra
(aiomqtt); nothing imports this package unless the configuration has ``mqtt:``."""

__all__: list[str] = []
