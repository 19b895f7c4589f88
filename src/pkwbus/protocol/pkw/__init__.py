"""The PKW parameter channel: PKE, IND and PWE, requests and responses.

Requests are built for a dialect (which request identifiers it has, how wide
its PNU is, whether it has a page index) and an IND layout; responses are
decoded with the same two, and :func:`matches` applies the rule of the
SINAMICS G120 CU240B-2/CU240E-2 Operating Instructions, section 6.3: the
response identifier fits, PNU and IND are the request's, and a change is
echoed in PWE.

This module gathers the channel's names from :mod:`pkwbus.protocol.pkw.fields`
(PKE, IND, PWE), :mod:`pkwbus.protocol.pkw.requests` and
:mod:`pkwbus.protocol.pkw.responses` (decoding and matching). They raise
:class:`~pkwbus.protocol.errors.LocalProtocolError` for what cannot be sent and
:class:`~pkwbus.protocol.errors.RemoteProtocolError` for what cannot be decoded.
"""

from __future__ import annotations

# The dialect's names this module has always made available, besides __all__.
from pkwbus.protocol.pkw.dialects import DWORD_COMMANDS as DWORD_COMMANDS
from pkwbus.protocol.pkw.dialects import WRITE_COMMANDS as WRITE_COMMANDS
from pkwbus.protocol.pkw.dialects import Command as Command
from pkwbus.protocol.pkw.dialects import Dialect as Dialect
from pkwbus.protocol.pkw.dialects import IndLayout as IndLayout
from pkwbus.protocol.pkw.dialects import Reply as Reply
from pkwbus.protocol.pkw.fields import (
    PAGE_SIZE,
    Store,
    Width,
    decode_pke_ind,
    encode_pke_ind,
    page_index,
    page_multiple,
)
from pkwbus.protocol.pkw.requests import (
    PkwRequest,
    decode_request,
    encode_request,
    none_request,
    read,
    read_description,
    read_parameter,
    read_text,
    request,
    write,
    write_text,
)
from pkwbus.protocol.pkw.responses import (
    NO_CHANGE_RIGHTS,
    ArrayCountResponse,
    ChangeDone,
    DescriptionResponse,
    NoResponse,
    PkwResponse,
    Rejection,
    SpontaneousResponse,
    TextResponse,
    ValueResponse,
    Verdict,
    decode_response,
    encode_response,
    judge,
    matches,
    rejections,
    response_id,
)

__all__ = [
    "NO_CHANGE_RIGHTS",
    "PAGE_SIZE",
    "ArrayCountResponse",
    "ChangeDone",
    "DescriptionResponse",
    "NoResponse",
    "PkwRequest",
    "PkwResponse",
    "Rejection",
    "SpontaneousResponse",
    "Store",
    "TextResponse",
    "ValueResponse",
    "Verdict",
    "Width",
    "decode_pke_ind",
    "decode_request",
    "decode_response",
    "encode_pke_ind",
    "encode_request",
    "encode_response",
    "judge",
    "matches",
    "none_request",
    "page_index",
    "page_multiple",
    "read",
    "read_description",
    "read_parameter",
    "read_text",
    "rejections",
    "request",
    "response_id",
    "write",
    "write_text",
]
