"""The long-running service around the bus master: configuration, metrics, API, audit."""

__all__: list[str] = []
