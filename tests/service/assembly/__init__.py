"""assembly."""

__all__: list[str] = []
