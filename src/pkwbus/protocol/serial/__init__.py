"""FC and USS telegrams on RS-485: STX/LGE/ADR/BCC framing, the streaming deframer and
character timing."""

__all__: list[str] = []
