"""wires."""

__all__: list[str] = []
