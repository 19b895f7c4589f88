"""`pkwbus backup` and `pkwbus restore`: a drive's settings to a backup document and back,
directly on the port (:mod:`.backup`, :mod:`.restore`)."""

__all__: list[str] = []
