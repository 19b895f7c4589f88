"""The write audit log: every write attempt, refused ones included, in SQLite
(:mod:`.log`, the store), with its rows (:mod:`.rows`), the key of its token
fingerprints (:mod:`.key`), the tallies of requests refused for want of a token
(:mod:`.refusals`), the check of the place it is kept (:mod:`.place`), and the
writer through which the HTTP API uses it off the event loop (:mod:`.writer`)."""

__all__: list[str] = []
