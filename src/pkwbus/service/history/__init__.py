"""What the drives remember, kept: their own fault and alarm logs, watched through the
lines' runners (:mod:`.watch`), each entry stored once in the history database
(:mod:`.store`, SQLite beside the audit log), whatever restarts and outages came between."""

__all__: list[str] = []
