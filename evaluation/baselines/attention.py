"""The attention baseline: one attention layer over the perceived entities, in numpy.

Each entity (and the aisle state) is a token; a learned query scores every token, a masked
softmax turns the scores into attention weights, and the weighted sum of the token
embeddings is classified into a command::

    H = tanh(X W_e + b_e)          token embeddings      (B, T, h)
    a = softmax_T(H q / sqrt(h))   attention weights     (B, T), padding masked out
    z = sum_t a_t H_t              pooled                (B, h)
    p = softmax(z W_o + b_o)       command probabilities (B, C)

Trained by full-batch Adam on cross-entropy with hand-written gradients (a test checks them
against finite differences). The weights ``a`` are what the attention "explanation" cites.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

__all__ = ["AttentionModel", "AttentionParams"]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
_MASKED = -1e9


@dataclass(slots=True)
class AttentionParams:
    w_e: FloatArray
    b_e: FloatArray
    q: FloatArray
    w_o: FloatArray
    b_o: FloatArray

    def arrays(self) -> list[FloatArray]:
        return [self.w_e, self.b_e, self.q, self.w_o, self.b_o]


@dataclass(slots=True)
class _Forward:
    h: FloatArray
    a: FloatArray
    z: FloatArray
    p: FloatArray


@dataclass(slots=True)
class AttentionModel:
    """Single-query attention pooling over entity tokens, then a linear softmax classifier."""

    n_in: int
    n_classes: int
    hidden: int = 16
    seed: int = 0
    params: AttentionParams = field(init=False)

    def __post_init__(self) -> None:
        rng = np.random.default_rng(self.seed)
        h = self.hidden
        self.params = AttentionParams(
            w_e=rng.normal(0.0, 1.0 / np.sqrt(self.n_in), (self.n_in, h)),
            b_e=np.zeros(h),
            q=rng.normal(0.0, 1.0 / np.sqrt(h), h),
            w_o=rng.normal(0.0, 1.0 / np.sqrt(h), (h, self.n_classes)),
            b_o=np.zeros(self.n_classes),
        )

    def _forward(self, x: FloatArray, mask: FloatArray) -> _Forward:
        p = self.params
        h = np.tanh(x @ p.w_e + p.b_e)
        scores = (h @ p.q) / np.sqrt(self.hidden)
        scores = np.where(mask > 0, scores, _MASKED)
        scores -= scores.max(axis=1, keepdims=True)
        a = np.exp(scores) * (mask > 0)
        a /= np.maximum(a.sum(axis=1, keepdims=True), 1e-12)
        z = np.einsum("bt,bth->bh", a, h)
        logits = z @ p.w_o + p.b_o
        logits -= logits.max(axis=1, keepdims=True)
        e = np.exp(logits)
        return _Forward(h, a, z, e / e.sum(axis=1, keepdims=True))

    def loss_and_grads(
        self, x: FloatArray, mask: FloatArray, y: IntArray
    ) -> tuple[float, list[FloatArray]]:
        """Mean cross-entropy and its gradient for each array of ``params.arrays()``."""
        p = self.params
        f = self._forward(x, mask)
        n = x.shape[0]
        loss = float(-np.mean(np.log(f.p[np.arange(n), y] + 1e-12)))
        d_logits = f.p.copy()
        d_logits[np.arange(n), y] -= 1.0
        d_logits /= n
        d_w_o = f.z.T @ d_logits
        d_b_o = d_logits.sum(axis=0)
        d_z = d_logits @ p.w_o.T
        d_h = f.a[:, :, None] * d_z[:, None, :]
        d_a = np.einsum("bth,bh->bt", f.h, d_z)
        d_s = f.a * (d_a - (f.a * d_a).sum(axis=1, keepdims=True))
        scale = 1.0 / np.sqrt(self.hidden)
        d_q = np.einsum("bt,bth->h", d_s, f.h) * scale
        d_h += d_s[:, :, None] * p.q[None, None, :] * scale
        d_u = d_h * (1.0 - f.h**2)
        d_w_e = np.einsum("bti,bth->ih", x, d_u)
        d_b_e = d_u.sum(axis=(0, 1))
        return loss, [d_w_e, d_b_e, d_q, d_w_o, d_b_o]

    def fit(
        self, x: FloatArray, mask: FloatArray, y: IntArray, steps: int = 400, lr: float = 0.03
    ) -> float:
        """Full-batch Adam; returns the final training loss."""
        arrays = self.params.arrays()
        m = [np.zeros_like(a) for a in arrays]
        v = [np.zeros_like(a) for a in arrays]
        b1, b2 = 0.9, 0.999
        loss = float("nan")
        for t in range(1, steps + 1):
            loss, grads = self.loss_and_grads(x, mask, y)
            for i, g in enumerate(grads):
                m[i] = b1 * m[i] + (1 - b1) * g
                v[i] = b2 * v[i] + (1 - b2) * g * g
                # in place: ``arrays`` are the model's own parameter arrays
                arrays[i] -= lr * (m[i] / (1 - b1**t)) / (np.sqrt(v[i] / (1 - b2**t)) + 1e-8)
        return loss

    def predict_proba(self, x: FloatArray, mask: FloatArray) -> FloatArray:
        return self._forward(x, mask).p

    def attend(self, x: FloatArray, mask: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(command probabilities, attention weights) for a batch."""
        f = self._forward(x, mask)
        return f.p, f.a
