"""The HTTP side of the service: the app with /metrics, /healthz, /readyz, the JSON
API under /api/v1 and the status page (:mod:`.api`, its bodies in :mod:`.models`, the
page's files in ``static/``); the parameter reads and audited writes behind the API
(:mod:`.parameters`, joining :mod:`.parameter_writes`: the write token here; the checks,
the reads, the one write path and what a job's outcome becomes in an answer and an audit
row in :mod:`pkwbus.service.writes`, shared with MQTT); and the bound on open connections
(:mod:`.connections`)."""

__all__: list[str] = []
