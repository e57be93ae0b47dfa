"""Compiled (numba) kernel of the residual composition (:class:`agents.rl.residual_env.ResidualController`).

Its numpy twin, which the tests compare it with bit for bit: :func:`agents.rl.residual_env.residual_torques`.
"""

from __future__ import annotations

from quad_uneven_env.jit import njit


@njit(nogil=True)
def residual_torques_into(  # pragma: no cover - compiled
    action, tau_expert, expert_gain, per_unit, scale, expert_basis, touch, foot_adr, gated, limit, out
):
    """out = clip(tau_base + residual, ±limit) with tau_base = ``tau_expert * expert_gain`` and residual =
    ``action * tau_base * scale`` (``expert_basis``) or ``action * per_unit``, zeroed on the legs whose foot's
    ``touch[foot_adr[leg]]`` is not > 0 when ``gated``; returns mean |tau_base + residual - tau_expert| (N m)
    before the clip, summed in numpy's pairwise order so it equals ``np.mean(np.abs(...))``."""
    n = out.shape[0]
    for i in range(n):
        base = tau_expert[i] * expert_gain[i]
        r = action[i] * base * scale if expert_basis else action[i] * per_unit[i]
        if gated:
            r = r * (1.0 if touch[foot_adr[i // 3]] > 0.0 else 0.0)
        out[i] = r + base
    total = pairwise_abs_diff_sum(out, tau_expert)
    for i in range(n):
        out[i] = min(max(out[i], -limit[i]), limit[i])
    return total / n


@njit(nogil=True)
def pairwise_abs_diff_sum(x, y):  # pragma: no cover - compiled
    """sum |x - y| in the order of numpy's pairwise summation for n <= 128 (eight accumulators, then the tail)."""
    n = x.shape[0]
    if n < 8:
        s = 0.0
        for i in range(n):
            s += abs(x[i] - y[i])
        return s
    r0, r1, r2, r3 = abs(x[0] - y[0]), abs(x[1] - y[1]), abs(x[2] - y[2]), abs(x[3] - y[3])
    r4, r5, r6, r7 = abs(x[4] - y[4]), abs(x[5] - y[5]), abs(x[6] - y[6]), abs(x[7] - y[7])
    stop = n - n % 8
    for i in range(8, stop, 8):
        r0 += abs(x[i] - y[i])
        r1 += abs(x[i + 1] - y[i + 1])
        r2 += abs(x[i + 2] - y[i + 2])
        r3 += abs(x[i + 3] - y[i + 3])
        r4 += abs(x[i + 4] - y[i + 4])
        r5 += abs(x[i + 5] - y[i + 5])
        r6 += abs(x[i + 6] - y[i + 6])
        r7 += abs(x[i + 7] - y[i + 7])
    s = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    for i in range(stop, n):
        s += abs(x[i] - y[i])
    return s


__all__ = ["pairwise_abs_diff_sum", "residual_torques_into"]
