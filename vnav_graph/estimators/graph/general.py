"""Interval information blocks as GTSAM ``HessianFactor`` pieces (used by ``isam2``)."""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ...types import FloatArray
from . import factors as gf


def hessian_pieces(keys: list[int], lam: FloatArray, eta: FloatArray,
                    active: tuple[int, ...]) -> list[Any]:
    """Split one group's information (16×16, η) into ≤3-key HessianFactors (pair cover)."""
    blocks = gf.BLOCKS
    sl = [slice(a, a + n) for a, n in blocks]
    if len(active) <= 3:
        trip = [tuple(active)]
    else:
        trip = [tr for tr in gf.PAIR_COVER]
    owned_pair: set[tuple[int, int]] = set()
    owned_diag: set[int] = set()
    out = []
    for tr in trip:
        tr = tuple(b for b in tr if b in active)
        gmat = {}
        gvec = {}
        for a_i, a in enumerate(tr):
            gvec[a] = (eta[sl[a]] if a not in owned_diag else np.zeros(blocks[a][1]))
            for b in tr[a_i:]:
                if a == b:
                    gmat[a, a] = lam[sl[a], sl[a]] if a not in owned_diag else \
                        np.zeros((blocks[a][1],) * 2)
                elif (a, b) in owned_pair:
                    gmat[a, b] = np.zeros((blocks[a][1], blocks[b][1]))
                else:
                    gmat[a, b] = lam[sl[a], sl[b]]
                    owned_pair.add((a, b))
        owned_diag.update(tr)
        kk = [keys[a] for a in tr]
        if len(tr) == 3:
            a, b, c = tr
            out.append(gtsam.HessianFactor(kk[0], kk[1], kk[2], gmat[a, a], gmat[a, b],
                                           gmat[a, c], gvec[a], gmat[b, b], gmat[b, c], gvec[b],
                                           gmat[c, c], gvec[c], 0.0))
        elif len(tr) == 2:
            a, b = tr
            out.append(gtsam.HessianFactor(kk[0], kk[1], gmat[a, a], gmat[a, b], gvec[a],
                                           gmat[b, b], gvec[b], 0.0))
        else:
            (a,) = tr
            out.append(gtsam.HessianFactor(kk[0], gmat[a, a], gvec[a], 0.0))
    return out
