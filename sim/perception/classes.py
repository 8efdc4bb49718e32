"""What a tracked object is: the class posterior's prior and its likelihoods per look.

A LiDAR look says something through the cluster's visible extent (all of it, or at least
this much when an edge is hidden); a camera detection through the detector's scores.
"""

from __future__ import annotations

import math

from sim.perception.clusters import Cluster
from sim.sensors import CLASSES, CameraDetection

__all__ = [
    "LOG_PRIOR",
    "argmax",
    "look_loglik",
    "normalize",
    "score_loglik",
    "width_at_least_loglik",
    "width_loglik",
]

# LiDAR extent per class: the visible extent (first to last return, m) lies anywhere in
# [low, high], measured with Gaussian error sd. A person (0.5 m across) shows 0.15-0.5 m
# (fewer beams far away); a pallet (1.2 x 1.0 m) one face or two, up to its 1.56 m diagonal;
# a forklift (2.4 x 1.2 m) its 1.2 m front up to its 2.7 m diagonal. Between 0.9 and 1.6 m
# the LiDAR cannot tell a pallet from a forklift, so it gives "forklift" no support there
# (a pallet's narrower range makes it the likelier of the two); only the camera can.
_EXTENT_MODEL = {
    "person": (0.15, 0.5, 0.08),
    "forklift": (0.9, 2.7, 0.1),
    "pallet": (0.9, 1.6, 0.1),
}
_PRIOR = {"person": 0.3, "forklift": 0.1, "pallet": 0.6}
"""What a new track is before its first look says otherwise: in a warehouse aisle most things
are goods; it also settles looks that say nothing (a sliver of a half-hidden pallet)."""
LOG_PRIOR = [math.log(_PRIOR[c]) for c in CLASSES]

# The class posterior has three entries: plain floats and ``math`` are several times faster
# than numpy at this size, and do not depend on which SIMD code numpy picks for exp and log.

_EXTENT_TERMS = [_EXTENT_MODEL[c] for c in CLASSES]
_SQRT2 = math.sqrt(2.0)
_SQRT2PI = math.sqrt(2.0 * math.pi)


def argmax(values: list[float]) -> int:
    """Index of the first largest value."""
    best = 0
    for i in range(1, len(values)):
        if values[i] > values[best]:
            best = i
    return best


def _phi_cdf(x: float) -> float:
    return 0.5 * math.erfc(-x / _SQRT2)


def width_loglik(width: float) -> list[float]:
    """log p(width | class): a uniform extent on [low, high] seen with Gaussian error."""
    return [
        math.log(
            max(1e-12, (_phi_cdf((hi - width) / sd) - _phi_cdf((lo - width) / sd)) / (hi - lo))
        )
        for lo, hi, sd in _EXTENT_TERMS
    ]


def width_at_least_loglik(width: float) -> list[float]:
    """log P(extent >= width | class): all a partly hidden cluster's width can say."""
    out = []
    for lo, hi, sd in _EXTENT_TERMS:
        # The mean over the uniform extent of P(error > width - extent), in closed form.
        a, b = (hi - width) / sd, (lo - width) / sd
        g_a = a * _phi_cdf(a) + math.exp(-0.5 * a * a) / _SQRT2PI
        g_b = b * _phi_cdf(b) + math.exp(-0.5 * b * b) / _SQRT2PI
        out.append(math.log(max(1e-12, sd * (g_a - g_b) / (hi - lo))))
    return out


def score_loglik(scores: tuple[float, ...]) -> list[float]:
    """log p(detector scores | class)."""
    return [math.log(s + 0.05) for s in scores]


def look_loglik(c: Cluster, seen_by: CameraDetection | None) -> list[float]:
    """log p(this look | class): the cluster's extent, plus the camera's scores if fused."""
    ll = width_at_least_loglik(c.width) if c.truncated else width_loglik(c.width)
    if seen_by is not None:
        ll = [a + b for a, b in zip(ll, score_loglik(seen_by.scores), strict=True)]
    return ll


def normalize(logp: list[float]) -> list[float]:
    """``logp`` shifted so that its probabilities sum to one."""
    m = max(logp)
    z = m + math.log(sum(math.exp(v - m) for v in logp))
    return [v - z for v in logp]
