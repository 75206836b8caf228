"""The bus wiring of the arm's drives: the arm file's buses (or topology file), else
firmware/protocol/buses.toml for six drives, else the fewest CAN FD 1/5 Mbit/s buses that fit the
drives within the bus budget at the loop rate; refused when a bus is over the budget."""

from __future__ import annotations

from typing import Any

from gen.arm.arm_file import ArmFile
from gen.arm.errors import ArmError
from gen.lib import busload
from gen.lib.busload import DEFAULT_TOPOLOGY
from gen.lib.params import constant

BUS_BUDGET: float = constant("bus-budget")  # the highest bus load the wiring may reach (the registry's)


def wiring(af: ArmFile, n: int, rate: float) -> list[dict[str, Any]]:
    try:
        if af.buses is not None:
            buses = busload.topology_from_doc({"bus": af.buses}, f"arm file {af.path}: buses", n)
        elif af.topology is not None:
            buses = busload.load_topology(af.topology, n)
        elif n == 6:
            buses = busload.load_topology(DEFAULT_TOPOLOGY, n)
        else:
            buses = busload.default_wiring(n, rate)
        loads = busload.compute(buses, rate, busload.HEARTBEAT_MS, busload.default_protocol(), n)
        over = [bl for bl in loads if bl.load > BUS_BUDGET]
        if over:
            raise busload.ConfigError(
                "; ".join(f"bus {bl.bus.name} ({bl.bus.describe()}, drives {bl.bus.drives}) is loaded "
                          f"{100 * bl.load:.0f} % at {rate:g} Hz, above the {100 * BUS_BUDGET:g} % budget "
                          f"(it fits up to {bl.max_rate_hz(BUS_BUDGET):.0f} Hz)" for bl in over)
                + ": spread the drives over more buses or use CAN FD (armctl busload --drives N shows the options)")
    except busload.ConfigError as exc:
        raise ArmError(f"bus wiring: {exc}") from exc
    return [{"name": b.name, "kind": "fd" if b.fd else "classic", "nominal": b.nominal_bps, "data": b.data_bps,
             "drives": b.drives} for b in buses]
