"""Split the n-joint problem into independent sub-problems when the weights allow it.

Both norms of a block-diagonal closed loop are the maximum over its blocks (H-infinity: the
largest singular value; generalized H2: the largest eigenvalue of C W C^T, block-diagonal), and
the plants are per joint, so joints that no weight couples can be designed separately without
losing optimality. Joints are coupled by an off-diagonal entry of H, or by a row of z_o
(a row of [E1 E2 D12]) that touches both. Identical sub-problems are solved once.
Solving the coupled n = 6 estimator takes ~10 s against ~0.05 s per joint, hence all this.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from gen.synth.config import DesignConfig


@dataclass(frozen=True)
class Component:
    joints: tuple[int, ...]
    rows: tuple[int, ...]  # rows of z_o that belong to these joints


def _union_find(n: int, links: list[tuple[int, int]]) -> list[list[int]]:
    parent = list(range(n))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in links:
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    return sorted(groups.values())


def components(cfg: DesignConfig) -> list[Component]:
    n = cfg.n_joints
    W = np.hstack([cfg.E1, cfg.E2, cfg.D12])  # p x 3n
    row_joints = [sorted({c % n for c in np.flatnonzero(W[r])}) for r in range(W.shape[0])]
    if cfg.structure == "coupled":
        return [Component(tuple(range(n)), tuple(r for r, js in enumerate(row_joints) if js))]
    links = [(i, j) for i in range(n) for j in range(n) if i != j and cfg.H[i, j] != 0.0]
    links += [(js[0], j) for js in row_joints for j in js[1:]]
    out = []
    for group in _union_find(n, links):
        g = set(group)
        rows = tuple(r for r, js in enumerate(row_joints) if js and g.issuperset(js))
        out.append(Component(tuple(group), rows))
    return out


def subproblem_key(cfg: DesignConfig, comp: Component) -> str:
    """Equal keys <=> numerically identical sub-problems (same F, H, E1, E2, D12 blocks)."""
    J, R = list(comp.joints), list(comp.rows)
    h = hashlib.sha256()
    for f in (cfg.F[j] for j in J):
        h.update(repr((f.num, f.den)).encode())
    for M in (cfg.H[np.ix_(J, J)], cfg.E1[np.ix_(R, J)], cfg.E2[np.ix_(R, J)], cfg.D12[np.ix_(R, J)]):
        h.update(repr(M.shape).encode())
        h.update(np.ascontiguousarray(M).tobytes())
    return h.hexdigest()
