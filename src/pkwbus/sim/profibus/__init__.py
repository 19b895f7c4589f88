"""Simulated PROFIBUS DP slaves on one line: start-up, PPO exchange, DP-V1, the live list."""

__all__: list[str] = []
