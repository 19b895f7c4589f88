"""The planner and what it needs: jobs, drive health, describing, the write gate and the
PKW transaction. Time and results in, actions out; it does not know which bus it serves."""

__all__: list[str] = []
