"""The `pkwbus` subcommands."""
