"""serial."""

__all__: list[str] = []
