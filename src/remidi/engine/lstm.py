"""An LSTM over a whole sequence, with its backward pass written out.

``lstm_over_time(kernel, bias, x, reset, carry)`` runs the cell of
:class:`flax.linen.OptimizedLSTMCell` over ``T`` steps for ``N`` envs, zeroing an env's carry
before a step where ``reset`` is True::

    c, h    = (0, 0) where reset[t] else (c, h)
    i f g o = split([x_t, h] · kernel + bias)          kernel f32[D + H, 4H], bias f32[4H]
    c'      = σ(f)·c + σ(i)·tanh(g);   h' = σ(o)·tanh(c')

Why a hand-written backward pass: differentiating the plain ``lax.scan`` makes XLA accumulate
the kernel's gradient inside the reversed loop, one ``[D + H, 32] × [32, 4H]`` product and a
``[D + H, 4H]`` addition per step (for the maze agent's 32 envs ≈ 20% of a PLR⊥ update on a
CPU, ``jax.profiler``: small products run far below the machine's rate and the addition is
memory-bound). Here
the reversed loop carries only what is sequential, the cotangents of ``(c, h)``; it stores each
step's gate gradients and computes the kernel's, bias's and inputs' gradients after the loop as
single large products over all ``T·N`` steps. Same mathematics as autodiff
(``tests/test_networks.py`` checks values and gradients against flax's cell). The inputs'
share of the gates stays inside the loop, as part of one ``[x, h]`` product: computing it for
all steps before the loop (one large product) measured slower on a CPU.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _cell(kernel, bias, carry, x_t, reset_t):
    """One step: ``(new carry, (xh, c_in, gates))``, ``gates`` = ``σ(i) σ(f) tanh(g) σ(o)``."""
    c, h = (jnp.where(reset_t[:, None], 0.0, v) for v in carry)
    xh = jnp.concatenate([x_t, h], axis=-1)
    i, f, g, o = jnp.split(xh @ kernel + bias, 4, axis=-1)
    i, f, g, o = jax.nn.sigmoid(i), jax.nn.sigmoid(f), jnp.tanh(g), jax.nn.sigmoid(o)
    c_new = f * c + i * g
    h_new = o * jnp.tanh(c_new)
    return (c_new, h_new), (xh, c, jnp.concatenate([i, f, g, o], axis=-1))


def _forward(kernel, bias, x, reset, carry, keep: bool):
    def step(carry, inputs):
        carry, saved = _cell(kernel, bias, carry, *inputs)
        return carry, (carry, saved if keep else None)

    carry, (per_step, saved) = jax.lax.scan(step, carry, (x, reset))
    return (carry, per_step[1]), (per_step[0], saved)


@jax.custom_vjp
def lstm_over_time(kernel, bias, x, reset, carry):
    """``((c, h) f32[N, H] each, y f32[T, N, H])`` for ``x f32[T, N, D]``, ``reset bool[T, N]``
    and the initial ``carry`` ``(c, h)``; ``y[t]`` is ``h`` after step ``t``."""
    return _forward(kernel, bias, x, reset, carry, keep=False)[0]


def _lstm_fwd(kernel, bias, x, reset, carry):
    out, (c_out, saved) = _forward(kernel, bias, x, reset, carry, keep=True)
    return out, (kernel, reset, c_out, saved)


def _lstm_bwd(residuals, cotangents):
    kernel, reset, c_out, (xh, c_in, gates) = residuals  # [T, N, ...] each
    (dc_last, dh_last), dy = cotangents
    d = xh.shape[-1] - c_in.shape[-1]
    recurrent_t = kernel[d:].T  # [4H, H]

    def step(carry, inputs):
        dc, dh = carry  # cotangents of the carry leaving this step
        dy_t, c_in_t, c_out_t, gates_t, reset_t = inputs
        i, f, g, o = jnp.split(gates_t, 4, axis=-1)
        dh = dh + dy_t
        tanh_c = jnp.tanh(c_out_t)
        dc = dc + dh * o * (1.0 - tanh_c * tanh_c)
        d_gates = jnp.concatenate([dc * g * i * (1.0 - i), dc * c_in_t * f * (1.0 - f), dc * i * (1.0 - g * g),
                                   dh * tanh_c * o * (1.0 - o)], axis=-1)  # pre-activation, [N, 4H]
        dc_in, dh_in = dc * f, d_gates @ recurrent_t
        # the carry entering this step was zeroed where the env restarted: no gradient flows back
        dc_in, dh_in = (jnp.where(reset_t[:, None], 0.0, v) for v in (dc_in, dh_in))
        return (dc_in, dh_in), d_gates

    (dc0, dh0), d_gates = jax.lax.scan(step, (dc_last, dh_last), (dy, c_in, c_out, gates, reset), reverse=True)
    flat_gates = d_gates.reshape(-1, d_gates.shape[-1])  # [T·N, 4H]
    d_kernel = xh.reshape(-1, xh.shape[-1]).T @ flat_gates
    d_x = d_gates @ kernel[:d].T  # [T, N, D]
    return d_kernel, flat_gates.sum(axis=0), d_x, None, (dc0, dh0)


lstm_over_time.defvjp(_lstm_fwd, _lstm_bwd)
