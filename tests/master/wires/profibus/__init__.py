"""profibus."""

__all__: list[str] = []
