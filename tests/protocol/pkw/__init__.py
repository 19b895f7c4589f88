"""pkw."""

__all__: list[str] = []
