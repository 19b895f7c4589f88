"""The `pkwbus` subcommands."""

__all__: list[str] = []
