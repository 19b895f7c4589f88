"""Hot standby of the lines over etcd (interface "Hot standby"; issue "hot standby").

:class:`Standby` campaigns for this instance's lines in etcd and holds them on a lease;
``on_change(line, held)`` tells the service when to start and stop a line, and
:meth:`Standby.fence` gives the port of a line the moment it must fall silent
(:class:`LineLeaseFence`). :class:`Marks` keeps a line's documents in etcd for its next
master. The engine never touches a port.

Modules: :mod:`.etcd` (the client, over etcd's JSON gateway), :mod:`.fence` (the margin
and the fence's arithmetic), :mod:`.keeper` (a lease renewed), :mod:`.view` (the keys as
read and watched), :mod:`.share` (the fair share), :mod:`.engine`, :mod:`.marks`.
"""

from pkwbus.service.standby.engine import Standby
from pkwbus.service.standby.etcd import EtcdError, EtcdRefused, EtcdUnavailable
from pkwbus.service.standby.fence import LineLeaseFence, margin
from pkwbus.service.standby.marks import Marks
from pkwbus.service.standby.view import Master

__all__ = [
    "EtcdError",
    "EtcdRefused",
    "EtcdUnavailable",
    "LineLeaseFence",
    "Marks",
    "Master",
    "Standby",
    "margin",
]
