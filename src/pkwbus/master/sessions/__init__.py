"""A command's line: jobs and probes on the one runner, ended early by a watcher."""

__all__: list[str] = []
