"""A planner for the stream task (armctl run --stream URL): publishes armlcm.plan_t on ARM_PLAN every
5 ms: the bundled arm's home for HOLD s, then the elbow and wrist_2 moving slowly for MOVE s, then
nothing (the stream goes stale: the controller holds the pose). Its last line: the last plan's q (rad,
JSON), where the arm is to be held.

    python tests/python/lcm_planner.py URL HOLD MOVE
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

import lcm  # noqa: E402

from gen import lcmtypes  # noqa: E402

HOME = [0.0, -1.3, 1.6, -1.87, -1.5708, 0.0]
SLOTS = 16  # plan_t's fixed arrays


def main(argv: list[str]) -> int:
    url, hold, move = argv[0], float(argv[1]), float(argv[2])
    armlcm = lcmtypes.load()
    lc = lcm.LCM(url)
    w = 2 * math.pi * 0.25
    t0 = time.monotonic()
    seq = 0
    while (t := time.monotonic() - t0) <= hold + move:
        q, qd, qdd = list(HOME), [0.0] * 6, [0.0] * 6
        s = max(t - hold, 0.0)
        for j, a in ((2, 0.1), (4, 0.15)):
            q[j] += a * (1 - math.cos(w * s))
            qd[j] = a * w * math.sin(w * s)
            qdd[j] = a * w * w * math.cos(w * s) if t > hold else 0.0
        m = armlcm.plan_t()
        m.seq, m.utime, m.n = seq, int(t * 1e6), 6
        m.q_d, m.qd_d, m.qdd_d = (x + [0.0] * (SLOTS - 6) for x in (q, qd, qdd))
        lc.publish("ARM_PLAN", m.encode())
        seq += 1
        time.sleep(0.005)
    print(f"lcm_planner: {seq} plans")
    print(json.dumps(q))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
