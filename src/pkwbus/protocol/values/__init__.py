"""Parameter notation, value types and conversion-index scaling, from their modules.

:mod:`pkwbus.protocol.values.notation` (``16-13``, ``r0021``, each drive's one name),
:mod:`pkwbus.protocol.values.types` (types and scaling) and
:mod:`pkwbus.protocol.values.encoding` (engineering values to raw numbers and back).
"""

from pkwbus.protocol.values.encoding import (
    MAX_DECIMAL_EXPONENT,
    check_limits,
    decode_text,
    decode_value,
    encode_exact,
    encode_text,
    encode_value,
)
from pkwbus.protocol.values.notation import (
    MAX_INDEX,
    MAX_PNU,
    ParameterNotationError,
    ParameterRef,
    canonical,
    danfoss_name,
    parse_parameter,
    siemens_name,
)
from pkwbus.protocol.values.types import (
    CONVERSION_FACTORS,
    DATA_TYPES,
    UNSCALED,
    Rounding,
    Scaling,
    ValueType,
    parse_type,
)

__all__ = [
    "CONVERSION_FACTORS",
    "DATA_TYPES",
    "MAX_DECIMAL_EXPONENT",
    "MAX_INDEX",
    "MAX_PNU",
    "UNSCALED",
    "ParameterNotationError",
    "ParameterRef",
    "Rounding",
    "Scaling",
    "ValueType",
    "canonical",
    "check_limits",
    "danfoss_name",
    "decode_text",
    "decode_value",
    "encode_exact",
    "encode_text",
    "encode_value",
    "parse_parameter",
    "parse_type",
    "siemens_name",
]
