"""The multicast groups the programs meet on when no SocketCAN is used: CAN frames over UDP and the
LCM telemetry. Their one definition is arm_controller's defaults (firmware/params/params.toml
[controller.bus] and [controller.lcm-url]); every Python side takes them from here. Both stay on
this host: routed to lo (TTL 0)."""

from __future__ import annotations

from gen.lib.params import default

_BUS: str = default("controller", "bus")          # udp:GROUP:PORT
_LCM_URL: str = default("controller", "lcm-url")  # udpm://GROUP:PORT?ttl=0

CAN_GROUP: str = _BUS.split(":")[1]
CAN_PORT: int = int(_BUS.split(":")[2])
LCM_GROUP: str = _LCM_URL.removeprefix("udpm://").split(":")[0]
LCM_PORT: int = int(_LCM_URL.removeprefix("udpm://").split(":")[1].split("?")[0])

# What `ip route` sends to lo: the LCM group alone, and the CAN group's /24 (a run slot's buses).
LCM_ROUTE = f"{LCM_GROUP}/32"
CAN_ROUTE = ".".join(CAN_GROUP.split(".")[:3]) + ".0/24"


def lcm_url(port: int, recv_buf: bool = False) -> str:
    """The LCM URL of the telemetry group on `port` (TTL 0; recv_buf: the receive buffer a logger
    asks for, so that a burst of a lockstep run is not dropped)."""
    return f"udpm://{LCM_GROUP}:{port}?ttl=0" + ("&recv_buf_size=8388608" if recv_buf else "")
