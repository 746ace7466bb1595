"""The learned belief model P(h | Λ): a GRU over an episode's (observation, action) pairs that
predicts the next observation, for the belief tracker.

Exact trackers fail when the env's randomness is in what the agent sees (:mod:`remidi.envs.noisy`);
the paper's appendix learns, with each adversary Λᵢ, a model of its trajectories instead:

* an :class:`ObsCoding` reads an observation as E categorical *entries* in ``[0, K)`` (the lever's
  one-hot: K = 2; the maze's image ``round(10·x)``: K = 11; its direction: K = 4);
* a GRU state ``h_t`` (zeros at an episode's start) predicts the next observation as E independent
  categoricals; the first observation is predicted from the zero state;
* the same state predicts whether the episode *continues* (Bernoulli), so a prefix that goes on
  where the adversary's episodes end is unlikely, as the exact tracker requires.

Pure, jit/vmap-friendly functions over dict params; coding, sizes and optimiser static. Shapes:
T steps, N envs, E entries, K categories, A actions, H hidden units, B frozen models."""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
import optax

from remidi.engine.core.seeds import cond_per_seed

# ---------------------------------------------------------------------------- observations
@dataclass(frozen=True)
class ObsCoding:
    """How an observation pytree reads as E categorical entries (static, hashable).

    Per leaf (``jax.tree.leaves`` order): category ``round(x · scales[i])`` clipped to
    ``[0, categories[i])``; the model uses ``max(categories)`` for every entry. ``sizes``: entries per
    leaf; ``ndims``: one observation's dims per leaf (its trailing dims in a batch)."""

    scales: tuple[float, ...]
    categories: tuple[int, ...]
    sizes: tuple[int, ...]
    ndims: tuple[int, ...] | None = None

    @property
    def num_entries(self) -> int:
        return sum(self.sizes)

    @property
    def num_categories(self) -> int:
        return max(self.categories)

    def encode(self, obs) -> jax.Array:
        """i32[..., E]: the categories of an observation with any leading batch dims."""
        leaves = jax.tree.leaves(obs)
        out = []
        ndims = self.ndims or (None,) * len(leaves)
        for leaf, scale, k, size, nd in zip(leaves, self.scales, self.categories, self.sizes, ndims):
            lead = leaf.shape[:leaf.ndim - (_event_ndim(leaf, size) if nd is None else nd)]
            flat = jnp.reshape(leaf, lead + (size,)).astype(jnp.float32)
            out.append(jnp.clip(jnp.round(flat * scale), 0, k - 1).astype(jnp.int32))
        return jnp.concatenate(out, axis=-1)


def _event_ndim(leaf, size: int) -> int:
    """How many trailing dims of ``leaf`` make one observation of ``size`` entries (coding without ``ndims``)."""
    n, prod = 0, 1
    while prod < size:
        n += 1
        prod *= leaf.shape[leaf.ndim - n]
    if prod != size:
        raise ValueError(f"an observation leaf of shape {leaf.shape} does not end in {size} entries")
    return n


def coding_for(example_obs, categories: dict | None = None) -> ObsCoding:
    """The coding of one unbatched observation ``example_obs``.

    ``categories``: ``{leaf name: (scale, K)}``; defaults: ``image`` ``(10, 11)`` (MiniGrid ids / 10),
    ``agent_dir`` ``(1, 4)``, anything else ``(1, 2)`` (one-hot vectors and bits)."""
    defaults = {"image": (10.0, 11), "agent_dir": (1.0, 4)}
    defaults.update(categories or {})
    scales, ks, sizes, ndims = [], [], [], []
    for path, leaf in jax.tree_util.tree_leaves_with_path(example_obs):
        name = getattr(path[-1], "name", None) if path else None
        scale, k = defaults.get(name, (1.0, 2))
        scales.append(float(scale))
        ks.append(int(k))
        sizes.append(max(1, math.prod(leaf.shape)))
        ndims.append(len(leaf.shape))
    return ObsCoding(scales=tuple(scales), categories=tuple(ks), sizes=tuple(sizes), ndims=tuple(ndims))


def coding_problem(coding: ObsCoding, obs) -> str | None:
    """Why ``coding`` cannot read ``obs`` (concrete, unbatched) losslessly, naming the leaf and a value; else None.

    Every value must be ``c / scale`` with ``c`` an integer in ``[0, K)``."""
    for (path, leaf), scale, k in zip(jax.tree_util.tree_leaves_with_path(obs), coding.scales, coding.categories):
        x = np.asarray(leaf, np.float64).ravel()
        c = x * scale
        bad = (np.abs(c - np.round(c)) > 1e-4) | (c < -1e-4) | (c > k - 1 + 1e-4)
        if bad.any():
            name = jax.tree_util.keystr(path)
            where = f"the observation field {name}" if name else "the observation"
            return (f"{where} holds {x[bad][0]:.4g}, which is no category "
                    f"round(x·{scale:g}) in [0, {k}) (the belief model reads discrete observations: one-hot or "
                    f"integer-coded entries)")
    return None


# ---------------------------------------------------------------------------- the model
@dataclass(frozen=True)
class BeliefModel:
    """A GRU next-observation model over ``coding``'s entries and the actions (static, hashable).

    ``num_actions``: ``n`` (actions ``i32[...]``) or a tuple of counts for ``MultiDiscrete``
    (``i32[..., k]``); each choice is one-hot coded."""

    coding: ObsCoding
    num_actions: int | tuple[int, ...]
    hidden: int = 64

    @property
    def action_shape(self) -> tuple[int, ...]:
        """An action's shape: ``()``, or ``(k,)`` for ``k`` components."""
        return (len(self.num_actions),) if isinstance(self.num_actions, tuple) else ()

    @property
    def input_size(self) -> int:
        counts = self.num_actions if isinstance(self.num_actions, tuple) else (self.num_actions,)
        return self.coding.num_entries * self.coding.num_categories + sum(counts)

    def action_code(self, action) -> jax.Array:
        """f32[..., Σ counts]: the action one-hot, component by component."""
        if not isinstance(self.num_actions, tuple):
            return jax.nn.one_hot(action, self.num_actions)
        return jnp.concatenate([jax.nn.one_hot(action[..., i], n) for i, n in enumerate(self.num_actions)], axis=-1)

    def init(self, rng) -> dict:
        """The parameters: GRU ``wx`` f32[D, 3H], ``wh`` f32[H, 3H], ``b`` f32[3H], ``bh`` f32[H]; head
        ``wo`` f32[H, E·K], ``bo`` f32[E·K]; continue logit ``wc`` f32[H], ``bc`` f32[]."""
        d, h, ek = self.input_size, self.hidden, self.coding.num_entries * self.coding.num_categories
        k1, k2, k3, k4 = jax.random.split(rng, 4)
        return {"wx": jax.random.normal(k1, (d, 3 * h)) / jnp.sqrt(d),
                "wh": jax.random.normal(k2, (h, 3 * h)) / jnp.sqrt(h),
                "b": jnp.zeros((3 * h,)), "bh": jnp.zeros((h,)),
                "wo": jax.random.normal(k3, (h, ek)) * 0.1 / jnp.sqrt(h), "bo": jnp.zeros((ek,)),
                "wc": jax.random.normal(k4, (h,)) * 0.1 / jnp.sqrt(h), "bc": jnp.zeros(())}

    def initial_hidden(self, batch_shape=()) -> jax.Array:
        """f32[..., H]: the state at an episode's start (zeros)."""
        return jnp.zeros(tuple(batch_shape) + (self.hidden,))

    def loglik(self, params, hidden, cats) -> jax.Array:
        """f32[...]: log P(``cats`` i32[..., E] | ``hidden`` f32[..., H])."""
        e, k = self.coding.num_entries, self.coding.num_categories
        logits = (hidden @ params["wo"] + params["bo"]).reshape(hidden.shape[:-1] + (e, k))
        logp = jax.nn.log_softmax(logits, axis=-1)
        return jnp.sum(jnp.take_along_axis(logp, cats[..., None], axis=-1)[..., 0], axis=-1)

    def continues(self, params, hidden, go_on) -> jax.Array:
        """f32[...]: log P(the episode continues where ``go_on`` bool[...], else ends | ``hidden`` after a step)."""
        logit = hidden @ params["wc"] + params["bc"]
        return jnp.where(go_on, jax.nn.log_sigmoid(logit), jax.nn.log_sigmoid(-logit))

    def cell(self, params, hidden, cats, action) -> jax.Array:
        """f32[..., H]: the state after seeing ``cats`` i32[..., E] and taking ``action``."""
        k = self.coding.num_categories
        x = jnp.concatenate([jax.nn.one_hot(cats, k).reshape(cats.shape[:-1] + (-1,)), self.action_code(action)],
                            axis=-1)
        gx = x @ params["wx"] + params["b"]
        gh = hidden @ params["wh"]
        h = self.hidden
        z = jax.nn.sigmoid(gx[..., :h] + gh[..., :h])
        r = jax.nn.sigmoid(gx[..., h:2 * h] + gh[..., h:2 * h])
        n = jnp.tanh(gx[..., 2 * h:] + r * (gh[..., 2 * h:] + params["bh"]))
        return (1.0 - z) * n + z * hidden


def step_logliks(model: BeliefModel, params, obs, action, reset) -> jax.Array:
    """f32[T, N]: log P(obs[t], and that the episode continued to t | the episode before t).

    ``obs`` leaves [T, N, ...], ``action`` i32[T, N], ``reset`` bool[T, N] (step t starts an episode;
    a rollout's first step always starts what it holds)."""
    return coded_logliks(model, params, model.coding.encode(obs), action, reset)


def coded_logliks(model: BeliefModel, params, cats, action, reset) -> jax.Array:
    """:func:`step_logliks` of coded observations ``cats`` int[T, N, E]."""
    obs_ll, went_on = _scan_logliks(model, params, cats, action, reset)
    return obs_ll + jnp.where(reset, 0.0, went_on)


def _scan_logliks(model: BeliefModel, params, cats, action, reset):
    """``(obs_ll f32[T, N], went_on f32[T, N])``: log P(obs[t] | episode before t) and log P(step t − 1's
    outcome: went on, or ended), 0 at the rollout's first step.

    A prefix's score includes ``went_on`` only where the episode went on; training sees both outcomes."""
    cats = cats.astype(jnp.int32)
    n = action.shape[1]

    def body(carry, inp):
        hidden, seen = carry  # seen: a step of this rollout came before (its state is in hidden)
        c, a, r = inp
        went_on = jnp.where(seen, model.continues(params, hidden, ~r), 0.0)  # a rollout's first step starts
        hidden = jnp.where(r[:, None], 0.0, hidden)
        return (model.cell(params, hidden, c, a), jnp.ones_like(seen)), (model.loglik(params, hidden, c), went_on)

    _, out = jax.lax.scan(body, (model.initial_hidden((n,)), jnp.zeros((n,), bool)), (cats, action, reset))
    return out


def episode_running(op, x, start) -> jax.Array:
    """[T, N]: ``op`` (``jnp.add``, ``jnp.minimum``) folded over ``x`` [T, N] along each episode so far,
    restarting where ``start`` bool[T, N] and at step 0."""

    def body(acc, inp):
        xt, s = inp
        acc = jnp.where(s, xt, op(acc, xt))
        return acc, acc

    return jax.lax.scan(body, x[0], (x, start.at[0].set(True)))[1]


def prefix_lengths(reset) -> jax.Array:
    """i32[T, N]: steps of each episode's prefix so far (step t included)."""
    return episode_running(jnp.add, jnp.ones(reset.shape, jnp.int32), reset)


def prefix_scores(ll, reset) -> jax.Array:
    """f32[T, N]: mean of ``ll`` f32[T, N] over each episode's prefix so far."""
    return episode_running(jnp.add, ll, reset) / prefix_lengths(reset)


def belief_loss(model: BeliefModel, params, obs, action, reset, mask=None) -> jax.Array:
    """f32[]: mean NLL per step (observation and outcome) over ``mask`` bool[T, N] (None: all); 0 if empty."""
    obs_ll, outcome = _scan_logliks(model, params, model.coding.encode(obs), action, reset)
    mask = jnp.ones(obs_ll.shape, bool) if mask is None else mask
    outcome = jnp.concatenate([outcome[1:], jnp.zeros_like(outcome[:1])])  # step t's outcome, seen at t + 1
    return -jnp.sum(jnp.where(mask, obs_ll + outcome, 0.0)) / jnp.maximum(jnp.sum(mask), 1)


def make_optimizer(lr: float = 1e-2, max_grad_norm: float = 1.0) -> optax.GradientTransformation:
    """The belief model's optimiser: Adam after global gradient-norm clipping."""
    return optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adam(lr))


@dataclass(frozen=True)
class LearnedSettings:
    """A learned tracker's ``remidi.belief_*`` keys: Adam ``lr``, ``epochs`` per rollout, calibration's
    ``false_rate``, ``margin``, ``spread``, ``calibration`` rollouts recorded, ``reference`` (judge by
    the ratio over a model of the task generator's trajectories)."""

    lr: float = 1e-2
    epochs: int = 4
    false_rate: float = 0.05
    margin: float = 1e-3
    spread: float = 0.0
    calibration: int = 16
    reference: bool = False

    @property
    def optimizer(self) -> optax.GradientTransformation:
        """The models' optimiser (:func:`make_optimizer`)."""
        return make_optimizer(self.lr)


def fit_step(model: BeliefModel, optimizer: optax.GradientTransformation, params, opt_state, obs, action, reset,
             mask=None):
    """``(params, opt_state, loss f32[])``: one Optax update on :func:`belief_loss` (loss before it)."""
    loss, grads = jax.value_and_grad(lambda p: belief_loss(model, p, obs, action, reset, mask))(params)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state, loss


def fit_steps(model: BeliefModel, optimizer: optax.GradientTransformation, params, opt_state, obs, action, reset,
              steps: int):
    """``(params, opt_state, losses f32[steps])``: ``steps`` :func:`fit_step` on one batch (``lax.scan``)."""

    def body(carry, _):
        p, o = carry
        p, o, loss = fit_step(model, optimizer, p, o, obs, action, reset)
        return (p, o), loss

    (params, opt_state), losses = jax.lax.scan(body, (params, opt_state), None, length=steps)
    return params, opt_state, losses



# ---------------------------------------------------------------------------- frozen models
def frozen_logliks(model: BeliefModel, params, hidden, cats) -> jax.Array:
    """f32[N, B]: each frozen model's (``params`` leaves [B, ...]) log-likelihood of ``cats`` [N, E]."""
    return jax.vmap(lambda p, h: model.loglik(p, h, cats), in_axes=(0, 1), out_axes=1)(params, hidden)


def frozen_step(model: BeliefModel, params, hidden, total, last, action, cats, done):
    """``(hidden [N, B, H], total [N, B])``: each frozen model one step on.

    From ``last`` [N, E] and ``action`` [N] (restarting where ``done`` bool[N]), adding the
    log-likelihood of ``cats`` [N, E] and of continuing: :func:`step_logliks` step by step."""
    cells = jax.vmap(lambda p, h: model.cell(p, h, last, action), in_axes=(0, 1), out_axes=1)(params, hidden)
    goes_on = jax.vmap(lambda p, h: model.continues(p, h, True), in_axes=(0, 1), out_axes=1)(params, cells)
    hidden = jnp.where(done[:, None, None], 0.0, cells)
    return hidden, jnp.where(done[:, None], 0.0, total + goes_on) + frozen_logliks(model, params, hidden, cats)


def init_reference(model: BeliefModel, optimizer, num_buffers: int, rng):
    """``(ref, ref_opt, ref_frozen)``: a fresh model of the task generator's trajectories, its optimiser
    state and its per-buffer frozen copies (leaves [K, ...])."""
    ref = model.init(jax.random.fold_in(rng, 1))
    return ref, optimizer.init(ref), jax.tree.map(lambda x: jnp.stack([x] * num_buffers), ref)


def freeze_reference(memory, active):
    """``memory.ref_frozen`` with the current reference frozen for buffer ``active`` (None without one)."""
    if memory.ref is None:
        return None
    return jax.tree.map(lambda all_, r: all_.at[active].set(r), memory.ref_frozen, memory.ref)


def earlier_references(memory):
    """The references frozen with the buffers before the last (leaves [K − 1, ...]; None without)."""
    return None if memory.ref_frozen is None else jax.tree.map(lambda x: x[:-1], memory.ref_frozen)


def fit_reference(model: BeliefModel, optimizer, memory, traj, epochs: int, fresh):
    """``memory`` with the reference fit ``epochs`` steps on ``traj`` where ``fresh`` bool[] (fresh levels)."""

    def fit(m):
        ref, ref_opt, _ = fit_steps(model, optimizer, m.ref, m.ref_opt, traj.obs, traj.action, traj.reset, epochs)
        return m.replace(ref=ref, ref_opt=ref_opt)

    return cond_per_seed(fresh, fit, lambda m: m, memory)
