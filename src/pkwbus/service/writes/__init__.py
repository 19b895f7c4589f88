"""The one path of a parameter's reads and audited writes, below every API that offers
them (HTTP, MQTT): the checks before anything is sent and the one error
(:mod:`.checks`), the on-demand reads (:mod:`.reads`), the write path (:mod:`.path`:
``writable``, limits, the audit row before the wire, the job, the read-back), and what
a job's outcome becomes in an answer and an audit row (:mod:`.outcomes`)."""

__all__: list[str] = []
