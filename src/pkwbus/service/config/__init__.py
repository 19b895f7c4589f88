"""The service's configuration file: strict pydantic models of its YAML.

Load it with :func:`load_config`; every problem, whatever its kind (unreadable
file, YAML syntax, duplicate key, unknown setting, wrong value, a parameter
the drive's dialect cannot encode), ends in one :class:`ConfigError` whose
``problems`` name their place::

    lines[0].drives[2].address: 130 is outside 1-126 for protocol fc

Environment:

- the write token is read from the variable named by ``api.write_token_env``
  (default ``PKWBUS_WRITE_TOKEN``) when asked for, with
  :meth:`Config.write_token`; it is never stored in the model, so it never
  shows in a repr, a log line or an error;
- ``PKWBUS_LISTEN`` (HOST:PORT), when set, replaces the file's ``listen``.

Each line is of its bus's class, picked by its ``protocol`` (a discriminated
union, :data:`Line`): :class:`FcLine`, :class:`UssLine` or
:class:`ProfibusLine`, with drives of the same bus (:class:`FcDrive`,
:class:`UssDrive`, :class:`ProfibusDrive`; :data:`Drive` is any of them). A
setting of another bus is refused with the bus it applies to
(``lines[0].drives[0].gsd: applies to protocol profibus only``).

Defaults that depend on the bus are filled in once the line is valid: a
drive's dialect (``fc`` on an FC line, ``uss`` on a USS line), its IND layout
(the dialect's), its PKW/PZD lengths (USS 4 and 2; FC fixed). The fields keep
what the file said; the resolved values are the properties
:attr:`~DriveBase.pkw_dialect`, :attr:`~DriveBase.layout` and
:attr:`~DriveBase.shape`; every line and drive has its ``protocol``.

The package's modules: :mod:`.base` (the error, the base model, constants),
:mod:`.fields` (field types), :mod:`.catalogs`, :mod:`.parameters`
(overrides and polls), :mod:`.drive` and :mod:`.line` (what every bus's
drives and lines have), :mod:`.serial` (FC and USS), :mod:`.profibus` (a DP
drive and its settings), :mod:`.profibus_line` (the DP line and what stops its
drives), :mod:`.mqtt` (the plant's broker), :mod:`.model` (the whole file),
:mod:`.loading`; and
:mod:`.line_load`, how busy each line of a valid configuration would be
(``pkwbus check-config``'s estimate, not re-exported here). Problems are
worded by :mod:`pkwbus.notation.problems`, shared with the catalogs; ``sim://`` ports
are parsed by :mod:`pkwbus.sim.serving.url`.
"""

from pkwbus.notation.durations import parse_duration
from pkwbus.service.config.base import (
    DEFAULT_LISTEN,
    DEFAULT_TOKEN_ENV,
    DIALECTS_BY_PROTOCOL,
    LISTEN_ENV,
    MAX_CONFIG_BYTES,
    MAX_HTTP_CONNECTIONS,
    PORT_SCHEMES,
    USS_MAX_ADDRESS,
    ConfigError,
)
from pkwbus.service.config.catalogs import CatalogLike, Catalogs, builtin_catalogs
from pkwbus.service.config.drive import DriveBase
from pkwbus.service.config.line import LineBase, Rs485
from pkwbus.service.config.loading import load_config, parse_config
from pkwbus.service.config.model import (
    Api,
    Config,
    Drive,
    Line,
    Listen,
    StandbyConfig,
    parse_listen,
)
from pkwbus.service.config.parameters import OVERRIDE_FIELDS, ParameterOverrides, Poll
from pkwbus.service.config.profibus import ProfibusDrive
from pkwbus.service.config.profibus_line import ProfibusLine
from pkwbus.service.config.serial import FcDrive, FcLine, UssDrive, UssLine
from pkwbus.sim.serving.url import SimPort, parse_sim_port

__all__ = [
    "DEFAULT_LISTEN",
    "DEFAULT_TOKEN_ENV",
    "DIALECTS_BY_PROTOCOL",
    "LISTEN_ENV",
    "MAX_CONFIG_BYTES",
    "MAX_HTTP_CONNECTIONS",
    "OVERRIDE_FIELDS",
    "PORT_SCHEMES",
    "USS_MAX_ADDRESS",
    "Api",
    "CatalogLike",
    "Catalogs",
    "Config",
    "ConfigError",
    "Drive",
    "DriveBase",
    "FcDrive",
    "FcLine",
    "Line",
    "LineBase",
    "Listen",
    "ParameterOverrides",
    "Poll",
    "ProfibusDrive",
    "ProfibusLine",
    "Rs485",
    "SimPort",
    "StandbyConfig",
    "UssDrive",
    "UssLine",
    "builtin_catalogs",
    "load_config",
    "parse_config",
    "parse_duration",
    "parse_listen",
    "parse_sim_port",
]
