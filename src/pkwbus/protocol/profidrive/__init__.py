"""PROFIdrive parameter access through data record 47: requests, responses and error texts."""

__all__: list[str] = []
