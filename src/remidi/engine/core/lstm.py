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
memory-bound). Here the reversed loop carries only what is sequential, the cotangents of
``(c, h)``, and the kernel's, bias's and inputs' gradients are single large products over all
``T·N`` steps after it. Same mathematics as autodiff (``tests/test_networks.py`` checks values
and gradients against flax's cell).

What keeps the loops short (each measured on a CPU, where every operation inside a loop over
time costs microseconds of its own):

- the bias is a row of the kernel, multiplied by a column of ones in ``[x_t, 1, h]``: no
  addition in the forward loop, and the bias's gradient is a row of the kernel's;
- the forward pass stores, per step, the factors that turn the cotangents of ``c`` and ``h``
  into the gates' (pre-activation) cotangents, so the reversed loop is two multiply-adds and
  one product instead of recomputing the gates' derivatives (``_lstm_bwd``), and it writes
  each step's gate cotangents over that step's factors (one ``[T, N, 4H]`` buffer, not two);
- the inputs' share of the gates stays inside the loop, as part of one ``[x, 1, h]`` product:
  computing it for all steps before the loop (one large product) measured no faster.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _joined(kernel, bias, d: int):
    """``[kernel's input rows; bias; kernel's recurrent rows]``: f32[D + 1 + H, 4H]."""
    return jnp.concatenate([kernel[:d], bias[None], kernel[d:]], axis=0)


def _forward(kernel, bias, x, reset, carry, keep: bool):
    """Run the cell over time. Returns ``((carry, y), saved)``; ``saved`` (with ``keep``) holds
    per step ``xh f32[T, N, D + 1 + H]`` (the product's input), ``factors f32[T, N, 4H]``,
    ``dc_dh f32[T, N, H]`` and ``forget f32[T, N, H]`` (see ``_lstm_bwd``)."""
    w = _joined(kernel, bias, x.shape[-1])
    ones = jnp.ones(x.shape[1:-1] + (1,), x.dtype)

    def step(carry, inputs):
        x_t, reset_t = inputs
        c, h = (jnp.where(reset_t[:, None], 0.0, v) for v in carry)
        xh = jnp.concatenate([x_t, ones, h], axis=-1)
        i, f, g, o = jnp.split(xh @ w, 4, axis=-1)
        i, f, g, o = jax.nn.sigmoid(i), jax.nn.sigmoid(f), jnp.tanh(g), jax.nn.sigmoid(o)
        c_new = f * c + i * g
        tanh_c = jnp.tanh(c_new)
        h_new = o * tanh_c
        if not keep:
            return (c_new, h_new), (h_new, None)
        # the gates' pre-activation cotangents are [dc, dc, dc, dh] · factors, where dc is the
        # cotangent of c_new including h_new's share: dc_next + dh · dc_dh
        factors = jnp.concatenate([g * i * (1.0 - i), c * f * (1.0 - f), i * (1.0 - g * g),
                                   tanh_c * o * (1.0 - o)], axis=-1)
        return (c_new, h_new), (h_new, (xh, factors, o * (1.0 - tanh_c * tanh_c), f))

    carry, (y, saved) = jax.lax.scan(step, carry, (x, reset))
    return (carry, y), saved


@jax.custom_vjp
def lstm_over_time(kernel, bias, x, reset, carry):
    """``((c, h) f32[N, H] each, y f32[T, N, H])`` for ``x f32[T, N, D]``, ``reset bool[T, N]``
    and the initial ``carry`` ``(c, h)``; ``y[t]`` is ``h`` after step ``t``."""
    return _forward(kernel, bias, x, reset, carry, keep=False)[0]


def _lstm_fwd(kernel, bias, x, reset, carry):
    out, saved = _forward(kernel, bias, x, reset, carry, keep=True)
    return out, (kernel, reset, saved)


def _lstm_bwd(residuals, cotangents):
    kernel, reset, (xh, factors, dc_dh, forget) = residuals  # [T, N, ...] each
    (dc_last, dh_last), dy = cotangents
    d = xh.shape[-1] - 1 - dc_dh.shape[-1]
    recurrent_t = kernel[d:].T  # [4H, H]
    num_steps = xh.shape[0]

    def step(s, carry):
        dc, dh, buffer = carry  # cotangents of the carry leaving step t; buffer: factors, then d_gates
        t = num_steps - 1 - s
        dh = dh + dy[t]
        dc = dc + dh * dc_dh[t]
        d_gates = jnp.concatenate([dc, dc, dc, dh], axis=-1) * buffer[t]  # pre-activation, [N, 4H]
        dc_in, dh_in = dc * forget[t], d_gates @ recurrent_t
        # the carry entering this step was zeroed where the env restarted: no gradient flows back
        dc_in, dh_in = (jnp.where(reset[t][:, None], 0.0, v) for v in (dc_in, dh_in))
        return dc_in, dh_in, buffer.at[t].set(d_gates)

    # each step's gate cotangents overwrite its factors, read just before: one [T, N, 4H] buffer
    dc0, dh0, d_gates = jax.lax.fori_loop(0, num_steps, step, (dc_last, dh_last, factors))
    flat_gates = d_gates.reshape(-1, d_gates.shape[-1])  # [T·N, 4H]
    d_joined = xh.reshape(-1, xh.shape[-1]).T @ flat_gates  # [D + 1 + H, 4H]
    d_x = d_gates @ kernel[:d].T  # [T, N, D]
    d_kernel = jnp.concatenate([d_joined[:d], d_joined[d + 1:]], axis=0)
    return d_kernel, d_joined[d], d_x, None, (dc0, dh0)


lstm_over_time.defvjp(_lstm_fwd, _lstm_bwd)
