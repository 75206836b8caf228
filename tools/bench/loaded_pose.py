"""An arm's most gravity-loaded pose: where its joints carry the largest share of their torque limit
against gravity, at rest (armctl faults runs every fault there: the pose a stop that drops the arm
would show most). Found on the arm's own MuJoCo model (the build's arm.xml), inside the joints'
ranges: a coarse grid over each joint's range, then coordinate refinement, deterministic."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

GRID = 9            # values per joint in the coarse search
REFINE_STEPS = 6    # halvings of the coordinate search's step
RANGE_MARGIN = 0.1  # rad kept from each end of a joint's range (the reference and the checks' margin)


@dataclass(frozen=True)
class LoadedPose:
    q: list[float]           # rad per joint
    gravity_nm: list[float]  # the torque each joint holds there
    load: list[float]        # |gravity| / torque limit, per joint


def _load(g: np.ndarray, limit: np.ndarray) -> tuple[float, float]:
    share = np.abs(g) / limit
    return float(share.max()), float(share.sum())  # the worst joint first, then the whole arm


def most_loaded_pose(arm_xml: Path) -> LoadedPose:
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(arm_xml))
    d = mujoco.MjData(m)
    n = m.nu
    joints = [int(m.actuator_trnid[i, 0]) for i in range(n)]
    lo = np.array([m.jnt_range[j, 0] + RANGE_MARGIN if m.jnt_limited[j] else -np.pi for j in joints])
    hi = np.array([m.jnt_range[j, 1] - RANGE_MARGIN if m.jnt_limited[j] else np.pi for j in joints])
    limit = np.abs(m.actuator_ctrlrange[:n, 1])

    def gravity(q: np.ndarray) -> np.ndarray:
        d.qpos[:] = 0.0
        d.qvel[:] = 0.0
        d.qpos[[m.jnt_qposadr[j] for j in joints]] = q
        mujoco.mj_forward(m, d)
        return d.qfrc_bias[[m.jnt_dofadr[j] for j in joints]].copy()

    # the first joint of a serial arm on a vertical base axis changes nothing: the grid leaves it at 0
    axes = [np.linspace(lo[i], hi[i], GRID) if i > 0 else np.array([min(max(0.0, lo[0]), hi[0])])
            for i in range(n)]
    best_q, best = None, (-1.0, -1.0)
    for q in np.array(np.meshgrid(*axes[: min(n, 4)], indexing="ij")).reshape(min(n, 4), -1).T:
        full = np.concatenate([q, np.clip(np.zeros(n - len(q)), lo[len(q):], hi[len(q):])])
        score = _load(gravity(full), limit)
        if score > best:
            best_q, best = full, score
    assert best_q is not None
    step = (hi - lo) / (GRID - 1)
    for _ in range(REFINE_STEPS):
        improved = True
        while improved:
            improved = False
            for i in range(n):
                for sign in (-1.0, 1.0):
                    q = best_q.copy()
                    q[i] = np.clip(q[i] + sign * step[i], lo[i], hi[i])
                    score = _load(gravity(q), limit)
                    if score > best:
                        best_q, best, improved = q, score, True
        step = step / 2
    g = gravity(best_q)
    return LoadedPose([float(x) for x in best_q], [float(x) for x in g], [float(x) for x in np.abs(g) / limit])
