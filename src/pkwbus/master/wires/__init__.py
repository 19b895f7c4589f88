"""The wires a runner drives, one per kind of bus: a few pure calls each (what to transmit
now, an answer came, a timeout), holding no runner."""

__all__: list[str] = []
