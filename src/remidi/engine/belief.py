"""A learned belief model P(h | Λ) for ReMiDi's distinguishability test in stochastic environments.

The exact trackers (:mod:`remidi.engine.tracker`) replay frozen levels and compare observations:
exact when the environment is deterministic given the level, useless when the environment's
randomness is in what the agent sees (:mod:`remidi.envs.noisy`). The paper's appendix proposes
instead to learn, with each adversary Λᵢ, a model of the trajectories it produces, and to call a
trajectory prefix *distinguishable* when its likelihood under every earlier adversary's model is
below a threshold. This module is that model, for discrete observations:

* an :class:`ObsCoding` reads an observation pytree as E *entries*, each a category in
  ``[0, K)`` (the lever's one-hot vector: K = 2 per entry; the maze's egocentric image, integers
  divided by 10: ``round(10·x)``, K = 11; its direction: K = 4);
* the model is a GRU over the episode's (observation, action) pairs whose state ``h_t`` (zeros at
  an episode's start) predicts the next observation as E independent categoricals (a
  *factorised* categorical); the first observation of an episode is predicted from the zero
  state, i.e. it is the adversary's distribution of first observations;
* the same state predicts whether the episode *continues* (a Bernoulli): at every later step of
  an episode the step's likelihood includes "it did not end before this step", and training also
  sees the steps where episodes did end, so a prefix that goes on where the adversary's episodes
  end is unlikely under its model, as the exact tracker requires that a frozen level's episode
  not end where the agent's goes on (where the agent's ends, both restart);
* :func:`step_logliks` gives ``log P(o_t, and that the episode went on to t | o_<t, a_<t)`` per
  step of a batch of trajectories
  (episodes delimited by ``reset``), :func:`prefix_scores` the mean log-likelihood per step of
  each episode's prefix so far (the score a threshold is compared with), :func:`fit_step` one
  Optax update on a batch, masked to the chosen steps;
* :func:`calibrate` turns held-out scores of the same adversary into the threshold with a stated
  false-distinguishable rate (``remidi.belief_false_rate``);
* :class:`BeliefTracker` is the tracker component (``start`` / ``explained`` / ``advance``
  over N envs, as :class:`~remidi.engine.tracker.ExactTracker`) reading the frozen adversaries'
  models and thresholds from ``frozen.belief`` (:class:`FrozenBeliefs`): a prefix is explained
  when its score under SOME valid frozen model is at least that model's threshold.

All functions are pure over pytrees (params are a dict of arrays) and jit/vmap-friendly; the
coding, sizes and optimiser are static. Shapes: T steps, N envs, E entries, K categories,
A actions, H hidden units, B frozen models.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from remidi.engine.seeds import cond_per_seed


# ---------------------------------------------------------------------------- observations
@dataclass(frozen=True)
class ObsCoding:
    """How an observation pytree reads as E categorical entries (static, hashable).

    Per leaf of the observation (in ``jax.tree.leaves`` order): ``scales[i]`` (an entry's
    category is ``round(x · scale)``, clipped to ``[0, categories[i])``). ``categories``: K of
    each leaf; the model uses ``max(categories)`` for every entry (an unused category simply
    gets no mass). ``sizes``: the number of entries of each leaf (its size); ``ndims``: the
    number of dims of one observation's leaf (its trailing dims in a batch)."""

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
        """i32[..., E]: the categories of an observation with any leading batch dims (the
        leaves' trailing dims are the ones of one observation, of ``sizes``)."""
        leaves = jax.tree.leaves(obs)
        out = []
        ndims = self.ndims or (None,) * len(leaves)
        for leaf, scale, k, size, nd in zip(leaves, self.scales, self.categories, self.sizes, ndims):
            lead = leaf.shape[:leaf.ndim - (_event_ndim(leaf, size) if nd is None else nd)]
            flat = jnp.reshape(leaf, lead + (size,)).astype(jnp.float32)
            out.append(jnp.clip(jnp.round(flat * scale), 0, k - 1).astype(jnp.int32))
        return jnp.concatenate(out, axis=-1)


def _event_ndim(leaf, size: int) -> int:
    """How many trailing dims of ``leaf`` make up one observation of ``size`` entries (for a
    coding built without ``ndims``)."""
    n, prod = 0, 1
    while prod < size:
        n += 1
        prod *= leaf.shape[leaf.ndim - n]
    if prod != size:
        raise ValueError(f"an observation leaf of shape {leaf.shape} does not end in {size} entries")
    return n


def coding_for(example_obs, categories: dict | None = None) -> ObsCoding:
    """The coding of the task's observation ``example_obs`` (one unbatched observation).

    ``categories`` maps a leaf's field name to ``(scale, K)``; unnamed leaves: the maze's
    ``image`` is ``(10, 11)`` (MiniGrid's object, colour and state ids divided by 10, K the most
    object types), ``agent_dir`` ``(1, 4)``, and any other leaf ``(1, 2)`` (one-hot vectors and
    bits, as the lever's)."""
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
    """Why ``coding`` cannot read the observation ``obs`` (one unbatched observation, concrete
    values) without losing information, or None: every value of a leaf must be a category
    ``c / scale`` with ``c`` an integer in ``[0, K)``. The message names the leaf and a value."""
    import numpy as np

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
    """A GRU next-observation model over ``coding``'s entries and ``num_actions`` discrete
    actions with ``hidden`` units (static, hashable: pass it as a static argument)."""

    coding: ObsCoding
    num_actions: int
    hidden: int = 64

    @property
    def input_size(self) -> int:
        return self.coding.num_entries * self.coding.num_categories + self.num_actions

    def init(self, rng) -> dict:
        """The parameters: GRU kernels ``wx`` f32[D, 3H], ``wh`` f32[H, 3H], biases ``b`` f32[3H],
        ``bh`` f32[H] (the candidate's recurrent bias), head ``wo`` f32[H, E·K], ``bo`` f32[E·K],
        and the episode-continues logit's ``wc`` f32[H], ``bc`` f32[]."""
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
        """f32[...]: log P(observation with categories ``cats`` i32[..., E] | state ``hidden`` f32[..., H])."""
        e, k = self.coding.num_entries, self.coding.num_categories
        logits = (hidden @ params["wo"] + params["bo"]).reshape(hidden.shape[:-1] + (e, k))
        logp = jax.nn.log_softmax(logits, axis=-1)
        return jnp.sum(jnp.take_along_axis(logp, cats[..., None], axis=-1)[..., 0], axis=-1)

    def continues(self, params, hidden, go_on) -> jax.Array:
        """f32[...]: log P(the episode continues, where ``go_on`` bool[...]; else ends | ``hidden``
        f32[..., H], the state after a step's observation and action)."""
        logit = hidden @ params["wc"] + params["bc"]
        return jnp.where(go_on, jax.nn.log_sigmoid(logit), jax.nn.log_sigmoid(-logit))

    def cell(self, params, hidden, cats, action) -> jax.Array:
        """f32[..., H]: the state after seeing ``cats`` i32[..., E] and taking ``action`` i32[...]."""
        k = self.coding.num_categories
        x = jnp.concatenate([jax.nn.one_hot(cats, k).reshape(cats.shape[:-1] + (-1,)),
                             jax.nn.one_hot(action, self.num_actions)], axis=-1)
        gx = x @ params["wx"] + params["b"]
        gh = hidden @ params["wh"]
        h = self.hidden
        z = jax.nn.sigmoid(gx[..., :h] + gh[..., :h])
        r = jax.nn.sigmoid(gx[..., h:2 * h] + gh[..., h:2 * h])
        n = jnp.tanh(gx[..., 2 * h:] + r * (gh[..., 2 * h:] + params["bh"]))
        return (1.0 - z) * n + z * hidden


def step_logliks(model: BeliefModel, params, obs, action, reset) -> jax.Array:
    """f32[T, N]: ``log P(obs[t], and at a later step of an episode that it continued | the
    episode's observations and actions before t)``.

    ``obs`` leaves [T, N, ...], ``action`` i32[T, N], ``reset`` bool[T, N] (step t starts an
    episode: the state restarts from zeros; a rollout's first step starts what it holds of its
    episode, marked or not)."""
    return coded_logliks(model, params, model.coding.encode(obs), action, reset)


def coded_logliks(model: BeliefModel, params, cats, action, reset) -> jax.Array:
    """:func:`step_logliks` of observations already coded, ``cats`` int[T, N, E]."""
    obs_ll, went_on = _scan_logliks(model, params, cats, action, reset)
    return obs_ll + jnp.where(reset, 0.0, went_on)


def _scan_logliks(model: BeliefModel, params, cats, action, reset):
    """(f32[T, N] ``log P(obs[t] | the episode before t)``, f32[T, N] ``log P(the episode went on
    to step t, where it did; else that it ended after step t − 1)``, 0 at the rollout's first
    step). The second is the outcome of step t − 1: a prefix's score includes it where the
    episode went on; where it ended the model learns from it, and the agent's next episode
    starts afresh."""
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
    """[T, N]: ``op`` (a binary function: ``jnp.add``, ``jnp.minimum``) folded over ``x`` [T, N]
    along each episode's steps so far (step t included), restarting where ``start`` bool[T, N]
    (and at step 0: a rollout's first step starts what it holds of its episode)."""

    def body(acc, inp):
        xt, s = inp
        acc = jnp.where(s, xt, op(acc, xt))
        return acc, acc

    return jax.lax.scan(body, x[0], (x, start.at[0].set(True)))[1]


def prefix_lengths(reset) -> jax.Array:
    """i32[T, N]: the number of steps of each episode's prefix so far (step t included)."""
    return episode_running(jnp.add, jnp.ones(reset.shape, jnp.int32), reset)


def prefix_scores(ll, reset) -> jax.Array:
    """f32[T, N]: the mean of ``ll`` f32[T, N] over each episode's steps so far (step t included)."""
    return episode_running(jnp.add, ll, reset) / prefix_lengths(reset)


def belief_loss(model: BeliefModel, params, obs, action, reset, mask=None) -> jax.Array:
    """f32[]: the mean negative log-likelihood per step over the steps of ``mask`` bool[T, N]
    (all if None), each step's observation and its outcome (the episode went on or ended after
    it); 0 when no step is masked in."""
    obs_ll, outcome = _scan_logliks(model, params, model.coding.encode(obs), action, reset)
    mask = jnp.ones(obs_ll.shape, bool) if mask is None else mask
    outcome = jnp.concatenate([outcome[1:], jnp.zeros_like(outcome[:1])])  # step t's outcome, seen at t + 1
    return -jnp.sum(jnp.where(mask, obs_ll + outcome, 0.0)) / jnp.maximum(jnp.sum(mask), 1)


def make_optimizer(lr: float = 1e-2, max_grad_norm: float = 1.0) -> optax.GradientTransformation:
    """The belief model's optimiser: Adam after global gradient-norm clipping."""
    return optax.chain(optax.clip_by_global_norm(max_grad_norm), optax.adam(lr))


def fit_step(model: BeliefModel, optimizer: optax.GradientTransformation, params, opt_state, obs, action, reset,
             mask=None):
    """One Optax update on a batch of trajectories (as :func:`belief_loss`). Returns
    ``(params, opt_state, loss f32[])`` (the loss before the update). An all-masked batch gives a
    zero gradient."""
    loss, grads = jax.value_and_grad(lambda p: belief_loss(model, p, obs, action, reset, mask))(params)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    return optax.apply_updates(params, updates), opt_state, loss


def fit_steps(model: BeliefModel, optimizer: optax.GradientTransformation, params, opt_state, obs, action, reset,
              steps: int):
    """``steps`` :func:`fit_step` updates on the same batch (one ``lax.scan``). Returns ``(params,
    opt_state, losses f32[steps])`` (each the loss before its update)."""

    def body(carry, _):
        p, o = carry
        p, o, loss = fit_step(model, optimizer, p, o, obs, action, reset)
        return (p, o), loss

    (params, opt_state), losses = jax.lax.scan(body, (params, opt_state), None, length=steps)
    return params, opt_state, losses


# ---------------------------------------------------------------------------- calibration
def num_length_buckets(max_length: int) -> int:
    """How many prefix-length buckets prefixes of at most ``max_length`` steps fill: lengths
    1, 2–3, 4–7, 8–15, ... (powers of two)."""
    return max(1, int(max_length).bit_length())


def length_bucket(length, num_buckets: int) -> jax.Array:
    """i32[...]: the bucket of each prefix length ≥ 1 (⌊log₂ length⌋, the last bucket for longer ones)."""
    lg = jnp.floor(jnp.log2(jnp.maximum(length, 1).astype(jnp.float32))).astype(jnp.int32)
    return jnp.minimum(lg, num_buckets - 1)


def calibrate(scores, false_rate: float, valid=None, slack: float = 1e-3) -> jax.Array:
    """f32[]: the threshold τ at which at most a fraction ``false_rate`` of the held-out prefix
    ``scores`` (f32[...], of trajectories of the model's own adversary; ``valid`` bool[...] picks
    them) lie strictly below: the (⌊false_rate·n⌋ + 1)-th smallest score, lowered by ``slack`` nats
    (scores recomputed step by step differ from the batch's by rounding). A prefix is then
    *explained* when its score is ≥ τ. With no valid score τ = +inf: the model explains nothing."""
    scores = jnp.ravel(scores)
    valid = jnp.ones(scores.shape, bool) if valid is None else jnp.ravel(valid)
    n = jnp.sum(valid)
    ordered = jnp.sort(jnp.where(valid, scores, jnp.inf))
    k = jnp.floor(false_rate * n).astype(jnp.int32)
    tau = ordered[jnp.minimum(k, scores.shape[0] - 1)] - slack
    return jnp.where(n > 0, tau, jnp.inf)


def calibrate_by_length(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                        slack: float = 1e-3) -> jax.Array:
    """f32[L]: :func:`calibrate` separately for the prefixes of each length bucket
    (:func:`length_bucket` of ``lengths`` i32[...], as ``scores``). A prefix's score is a mean
    over its steps, so short prefixes (the first observation alone) spread far wider than long
    ones, and one threshold over all lengths would be set by the short ones and let long prefixes
    of other adversaries through. A bucket with too few held-out prefixes for its quantile (fewer
    than ⌈1/false_rate⌉, one for a rate of 0) takes the threshold of the bucket below it (the
    first bucket: the threshold of all lengths together)."""
    scores, lengths = jnp.ravel(scores), jnp.ravel(lengths)
    valid = jnp.ones(scores.shape, bool) if valid is None else jnp.ravel(valid)
    pooled = calibrate(scores, false_rate, valid, slack)
    bucket = length_bucket(lengths, num_buckets)
    needed = math.ceil(1.0 / false_rate) if false_rate > 0 else 1

    def one(b):
        mine = valid & (bucket == b)
        return calibrate(scores, false_rate, mine, slack), jnp.sum(mine) >= needed

    taus, enough = jax.vmap(one)(jnp.arange(num_buckets))

    def inherit(previous, x):
        tau, ok = x
        tau = jnp.where(ok, tau, previous)
        return tau, tau

    return jax.lax.scan(inherit, pooled, (taus, enough))[1]


def episode_minimum(z, lengths) -> jax.Array:
    """f32[T, N]: the running minimum of ``z`` f32[T, N] over each episode's prefix so far
    (``lengths`` i32[T, N], :func:`prefix_lengths`: 1 starts an episode)."""
    return episode_running(jnp.minimum, z, lengths == 1)


def calibrate_monotone(scores, lengths, false_rate: float, num_buckets: int, valid=None,
                       margin: float = 1e-3) -> jax.Array:
    """f32[L]: thresholds per prefix-length bucket for the *monotone* judgement the tracker makes
    (a prefix is explained when it and every shorter prefix of its episode reach their
    thresholds: a prefix an adversary cannot produce has no extension it can produce). Per bucket
    :func:`calibrate_by_length`; then all are lowered together until at most ``false_rate`` of
    the held-out prefixes have a shorter prefix below its threshold (the ``false_rate`` quantile
    of ``min over the episode so far of (score − τ)``), and by ``margin`` nats per step.
    ``scores``, ``lengths``, ``valid``: [R, T, N] (rows of T steps of N envs, time-major)."""
    tau = calibrate_by_length(scores, lengths, false_rate, num_buckets, valid)
    z = scores - tau[length_bucket(lengths, num_buckets)]
    low = jax.vmap(episode_minimum)(z, lengths)  # [R, T, N]
    shift = calibrate(low, false_rate, valid, slack=0.0)
    shift = jnp.where(jnp.isfinite(shift), jnp.minimum(shift, 0.0), 0.0)
    return tau + shift - margin


# ---------------------------------------------------------------------------- frozen models
def frozen_logliks(model: BeliefModel, params, hidden, cats) -> jax.Array:
    """f32[N, B]: each frozen model's (``params`` leaves [B, ...]) log-likelihood of ``cats``
    [N, E] from ``hidden`` [N, B, H]."""
    return jax.vmap(lambda p, h: model.loglik(p, h, cats), in_axes=(0, 1), out_axes=1)(params, hidden)


def frozen_step(model: BeliefModel, params, hidden, total, last, action, cats, done):
    """Each frozen model (``params`` leaves [B, ...]) one step on: its state [N, B, H] after the
    last observation ``last`` [N, E] and ``action`` [N] (zeros where ``done`` bool[N]: an episode
    starts), and the summed log-likelihood ``total`` [N, B] of the episode with ``cats`` [N, E]
    (and, where it goes on, with its continuing: :func:`step_logliks` step by step)."""
    cells = jax.vmap(lambda p, h: model.cell(p, h, last, action), in_axes=(0, 1), out_axes=1)(params, hidden)
    goes_on = jax.vmap(lambda p, h: model.continues(p, h, True), in_axes=(0, 1), out_axes=1)(params, cells)
    hidden = jnp.where(done[:, None, None], 0.0, cells)
    return hidden, jnp.where(done[:, None], 0.0, total + goes_on) + frozen_logliks(model, params, hidden, cats)


def init_reference(model: BeliefModel, optimizer, num_buffers: int, rng):
    """A fresh reference model of the task generator's trajectories: ``(ref, ref_opt, ref_frozen)``,
    its parameters, its optimiser state and its copies for the ``num_buffers`` buffers (leaves
    [K, ...], each set by :func:`freeze_reference` when its buffer is frozen)."""
    ref = model.init(jax.random.fold_in(rng, 1))
    return ref, optimizer.init(ref), jax.tree.map(lambda x: jnp.stack([x] * num_buffers), ref)


def freeze_reference(memory, active):
    """``memory.ref_frozen`` (any memory with ``ref`` and ``ref_frozen``; None without a reference)
    with the reference as it is now frozen for buffer ``active``."""
    if memory.ref is None:
        return None
    return jax.tree.map(lambda all_, r: all_.at[active].set(r), memory.ref_frozen, memory.ref)


def earlier_references(memory):
    """The references frozen with the buffers before the last (leaves [K − 1, ...]; None without
    a reference): what the rollout's tracker reads, as its frozen models."""
    return None if memory.ref_frozen is None else jax.tree.map(lambda x: x[:-1], memory.ref_frozen)


def fit_reference(model: BeliefModel, optimizer, memory, traj, epochs: int, fresh):
    """``memory`` (any with ``ref`` and ``ref_opt``) with the generator's reference model fit
    ``epochs`` steps on ``traj``, a rollout of fresh levels (``fresh`` bool[]; else unchanged)."""

    def fit(m):
        ref, ref_opt, _ = fit_steps(model, optimizer, m.ref, m.ref_opt, traj.obs, traj.action, traj.reset, epochs)
        return m.replace(ref=ref, ref_opt=ref_opt)

    return cond_per_seed(fresh, fit, lambda m: m, memory)


# ---------------------------------------------------------------------------- the tracker
@struct.dataclass
class FrozenBeliefs:
    """The frozen adversaries' models: ``params`` leaves [B, ...], ``threshold`` f32[B, L] (per
    prefix-length bucket, :func:`length_bucket`) or f32[B] (one for all lengths), ``valid``
    bool[B] (the adversary has been frozen)."""

    params: Any
    threshold: jax.Array
    valid: jax.Array
    ref: Any = None  # remidi.belief_reference: the generator's reference model frozen with each, leaves [B, ...]


@struct.dataclass
class BeliefState:
    """The tracker state of one env (leaves [N, ...] in the component) over B frozen models."""

    hidden: jax.Array  # f32[B, H]: each model's state before the current observation
    total: jax.Array  # f32[B]: the episode's summed log-likelihood so far under each model
    count: jax.Array  # i32[]: the episode's steps so far
    last: jax.Array  # i32[E]: the current observation's categories (the next step's input)
    match: jax.Array  # bool[B]: model b explains the prefix (it and every shorter one reach their thresholds)
    ref_hidden: Any = None  # f32[B, H]: with a reference, its frozen copies' states ...
    ref_total: Any = None  # f32[B]: ... and summed log-likelihoods (the score is the difference)


@dataclass(frozen=True)
class BeliefTracker:
    """The tracker component judging distinguishability by learned belief models (the frozen
    adversaries' models in ``frozen.belief``, :class:`FrozenBeliefs`): env n's prefix is
    explained by model b when its mean log-likelihood per step under b, and that of every shorter
    prefix of the episode, reaches b's threshold for its length (monotone, as realisability is:
    once distinguishable, the rest of the episode is); explained when some valid model explains
    it. Methods as :class:`~remidi.engine.tracker.ExactTracker`'s, on leaves [N, ...]; the frozen
    levels themselves are not stepped."""

    model: BeliefModel

    def _judge(self, frozen, total, count, ref_total=None) -> jax.Array:
        """bool[N, B]: each valid frozen model's threshold is reached by the env's prefix score
        (with a reference: the log-likelihood ratio of the frozen model over its reference)."""
        b = frozen.belief
        score = (total if ref_total is None else total - ref_total) / jnp.maximum(count, 1)[:, None]
        if b.threshold.ndim == 1:
            tau = b.threshold[None, :]
        else:  # each env's threshold for its prefix's length: [N, B]
            tau = b.threshold[:, length_bucket(count, b.threshold.shape[1])].T
        return b.valid[None, :] & (score >= tau)

    def start(self, env, params, frozen, reset_keys, obs, starts=None) -> BeliefState:
        """The state at the envs' first observations ``obs`` (leaves [N, ...])."""
        n = reset_keys.shape[0]
        cats = self.model.coding.encode(obs)  # [N, E]
        hidden = self.model.initial_hidden((n, frozen.belief.threshold.shape[0]))
        total, count = frozen_logliks(self.model, frozen.belief.params, hidden, cats), jnp.ones((n,), jnp.int32)
        ref_hidden = ref_total = None
        if frozen.belief.ref is not None:
            ref_hidden, ref_total = hidden, frozen_logliks(self.model, frozen.belief.ref, hidden, cats)
        return BeliefState(hidden=hidden, total=total, count=count, last=cats,
                           match=self._judge(frozen, total, count, ref_total), ref_hidden=ref_hidden,
                           ref_total=ref_total)

    def explained(self, state: BeliefState) -> jax.Array:
        """bool[N]: some frozen model explains each env's prefix so far."""
        return jnp.any(state.match, axis=-1)

    def advance(self, env, params, frozen, env_keys, state: BeliefState, action, next_obs, done) -> BeliefState:
        """After the envs took ``action`` i32[N] and saw ``next_obs`` (the next episode's first
        observation where ``done`` bool[N])."""
        cats = self.model.coding.encode(next_obs)  # [N, E]
        hidden, total = frozen_step(self.model, frozen.belief.params, state.hidden, state.total, state.last, action,
                                    cats, done)
        ref_hidden = ref_total = None
        if frozen.belief.ref is not None:
            ref_hidden, ref_total = frozen_step(self.model, frozen.belief.ref, state.ref_hidden, state.ref_total,
                                                state.last, action, cats, done)
        count = jnp.where(done, 0, state.count) + 1
        fresh = self._judge(frozen, total, count, ref_total)
        return BeliefState(hidden=hidden, total=total, count=count, last=cats,
                           match=jnp.where(done[:, None], fresh, state.match & fresh), ref_hidden=ref_hidden,
                           ref_total=ref_total)

    def overflow(self, state: BeliefState) -> jax.Array:
        return jnp.zeros(state.count.shape, jnp.int32)

    def buffer_match(self, state: BeliefState, num_buffers: int, capacity: int) -> jax.Array:
        """bool[N, B]: frozen model b explains env n's prefix (Combine: one model per buffer)."""
        return state.match[:, :num_buffers]


# ---------------------------------------------------------------------------- in a run
@struct.dataclass
class BeliefMemory:
    """What a ReMiDi run with ``remidi.tracker=belief`` carries (``Runner.belief``): one model per
    adversary (a buffer of the sequence, or a generator), trained while it is active and frozen
    with it.

    ``params`` leaves [K, ...] (model k: adversary k's); ``opt_state``: the active model's
    optimiser state (restarted at each switch); ``threshold`` f32[K, L] (per prefix-length
    bucket, :func:`calibrate_by_length`; +inf until calibrated at the model's freeze);
    ``scores`` f32[R, T, N] and ``lengths`` i32[R, T, N]: the prefix scores (and prefix lengths) of
    the active adversary's last R rollouts of its own levels (a buffer's replays, a generator's
    updates), each under the model as it was before fitting on that rollout (held out from it);
    ``written`` i32[]: rollouts recorded since the switch (row ``written mod R`` is next);
    ``fits`` i32[]: rollouts the active model has learnt from since the switch. The first one's
    scores are not recorded: they are those of the untrained model, whose scores sit near the
    uniform model's, and a threshold calibrated on them would let every prefix through."""

    params: Any
    opt_state: Any
    threshold: jax.Array
    scores: jax.Array
    lengths: jax.Array
    written: jax.Array
    fits: jax.Array
    # remidi.belief_reference: a model of the task generator's trajectories (the rollouts of fresh
    # levels), ``ref`` (learning all run, ``ref_opt`` its optimiser state), copied into
    # ``ref_frozen`` [K, ...] when adversary k is frozen; scores are then log-likelihood ratios
    ref: Any = None
    ref_opt: Any = None
    ref_frozen: Any = None
    # ... and the recorded rollouts themselves (coded observations i8[R, T, N, E], actions i32[R, T, N],
    # resets bool[R, T, N]), so that at the freeze the reference's part of each recorded ratio is
    # computed by the frozen reference, the one that will judge (``scores`` then holds the model's part)
    codes: Any = None
    actions: Any = None
    resets: Any = None


def init_memory(model: BeliefModel, optimizer, num_buffers: int, rows: int, num_steps: int, num_envs: int,
                rng, max_length: int | None = None, reference: bool = False) -> BeliefMemory:
    """Fresh models for ``num_buffers`` adversaries (independent initialisations from ``rng``),
    a calibration record of ``rows`` replays of T·N prefix scores each (T = ``num_steps``); the
    prefix lengths, at most ``min(T, max_length)`` (the episode limit), set the length buckets
    (:func:`num_length_buckets`)."""
    params = jax.vmap(model.init)(jax.random.split(rng, num_buffers))
    first = jax.tree.map(lambda x: x[0], params)
    batch = (num_steps, num_envs)
    ref = ref_opt = ref_frozen = codes = actions = resets = None
    if reference:
        ref, ref_opt, ref_frozen = init_reference(model, optimizer, num_buffers, rng)
        codes = jnp.zeros((rows,) + batch + (model.coding.num_entries,), jnp.int8)
        actions, resets = jnp.zeros((rows,) + batch, jnp.int32), jnp.ones((rows,) + batch, bool)
    return BeliefMemory(ref=ref, ref_opt=ref_opt, ref_frozen=ref_frozen, codes=codes, actions=actions, resets=resets,
                        params=params, opt_state=optimizer.init(first),
                        threshold=jnp.full((num_buffers, num_length_buckets(min(num_steps, max_length or num_steps))),
                                           jnp.inf, jnp.float32),  # strongly typed, as a checkpoint restores it
                        scores=jnp.zeros((rows,) + batch), lengths=jnp.ones((rows,) + batch, jnp.int32),
                        written=jnp.zeros((), jnp.int32), fits=jnp.zeros((), jnp.int32))


def frozen_beliefs(memory: BeliefMemory, active) -> FrozenBeliefs:
    """The models of the buffers before ``active`` (B = K − 1 entries, the last never frozen)."""
    k = memory.threshold.shape[0]
    return FrozenBeliefs(params=jax.tree.map(lambda x: x[:-1], memory.params), threshold=memory.threshold[:-1],
                         valid=jnp.arange(k - 1) < active, ref=earlier_references(memory))


def learn(model: BeliefModel, optimizer, memory: BeliefMemory, active, traj, trained,
          epochs: int = 1, fresh=None) -> tuple[BeliefMemory, jax.Array]:
    """The active adversary's model learns from a rollout of its levels (``trained`` bool[]: the
    rollout played the adversary's own levels, a replay of its buffer or a generator's levels;
    otherwise nothing changes): record the rollout's prefix scores under the model before the
    update (held out; not for the model's first rollout since the switch, whose scores are the
    untrained model's), then ``epochs`` :func:`fit_step` on all
    its steps. ``traj``: a :class:`~remidi.engine.rollout.Trajectory` (leaves [T, N, ...]). Returns
    ``(memory, loss f32[]: the first epoch's, NaN when not trained)``.

    With a reference (``memory.ref``, :func:`freeze` judges by the ratio over it): the rollout is
    recorded too, for the frozen reference's part of the ratio; the reference itself learns from
    rollouts of the task generator's fresh levels (``fresh`` bool[])."""

    def fit(m: BeliefMemory):
        params = jax.tree.map(lambda x: x[active], m.params)
        ll = step_logliks(model, params, traj.obs, traj.action, traj.reset)
        scores = prefix_scores(ll, traj.reset)  # [T, N]
        rows = m.scores.shape[0]

        params, opt_state, losses = fit_steps(model, optimizer, params, m.opt_state, traj.obs, traj.action,
                                              traj.reset, epochs)
        loss = losses[0]
        record = m.fits > 0
        row = jnp.where(record, m.written % rows, rows)  # rows: out of bounds, dropped
        lengths = prefix_lengths(traj.reset)
        if m.ref is not None:
            m = m.replace(codes=m.codes.at[row].set(model.coding.encode(traj.obs).astype(jnp.int8), mode="drop"),
                          actions=m.actions.at[row].set(traj.action, mode="drop"),
                          resets=m.resets.at[row].set(traj.reset, mode="drop"))
        return m.replace(params=jax.tree.map(lambda all_, p: all_.at[active].set(p), m.params, params),
                         opt_state=opt_state, scores=m.scores.at[row].set(scores, mode="drop"),
                         lengths=m.lengths.at[row].set(lengths, mode="drop"),
                         written=m.written + record.astype(jnp.int32), fits=m.fits + 1), loss

    memory, loss = cond_per_seed(trained, fit, lambda m: (m, jnp.float32(jnp.nan)), memory)
    if memory.ref is None:
        return memory, loss

    return fit_reference(model, optimizer, memory, traj, epochs, fresh), loss


def heldout_score(memory: BeliefMemory) -> jax.Array:
    """f32[]: the mean of the recorded held-out prefix scores of the active model's replays (its own
    log-likelihood, also with a reference, whose part is computed only at the freeze; the
    units of its threshold; NaN until the second replay since the switch, the first recorded)."""
    rows = memory.scores.shape[0]
    recorded = (jnp.arange(rows) < memory.written)[:, None, None]
    per_row = memory.scores[0].size
    total = jnp.sum(jnp.where(recorded, memory.scores, 0.0))
    return total / jnp.where(memory.written > 0, jnp.minimum(memory.written, rows) * per_row, jnp.nan)


def uniform_score(model: BeliefModel) -> float:
    """The per-step log-likelihood of a model that knows nothing (every entry uniform over its
    leaf's categories; the first step's, which has no continues factor, as ``belief/threshold``
    is the one-step prefixes'): a frozen model whose held-out scores are near this one explains
    anything its adversary could show, and its threshold lets nearly every prefix through."""
    c = model.coding
    return -sum(size * math.log(k) for size, k in zip(c.sizes, c.categories))


def freeze(optimizer, memory: BeliefMemory, active, switch, false_rate: float, margin: float = 1e-3,
           model: BeliefModel | None = None) -> BeliefMemory:
    """At a buffer switch (``switch`` bool[]) the active model is frozen: its thresholds are
    calibrated on the recorded scores per prefix-length bucket for the monotone judgement
    (:func:`calibrate_monotone`; +inf, explaining nothing, if no replay was recorded: the model
    learnt from at most one replay) and lowered by ``margin`` nats per step, the record emptied
    and the optimiser restarted for the next model. Computed only at a switch. With a reference
    (``model`` needed) the recorded scores become ratios: minus the frozen reference's prefix
    scores of the recorded rollouts, computed now by the reference that is frozen with the model."""

    def switched(m: BeliefMemory) -> BeliefMemory:
        rows, k = m.scores.shape[0], m.threshold.shape[0]
        valid = jnp.broadcast_to((jnp.arange(rows) < m.written)[:, None, None], m.scores.shape)
        scores = m.scores
        if m.ref is not None:
            ref_ll = jax.vmap(lambda c, a, r: coded_logliks(model, m.ref, c, a, r))(m.codes, m.actions, m.resets)
            scores = scores - jax.vmap(prefix_scores)(ref_ll, m.resets)
        tau = calibrate_monotone(scores, m.lengths, false_rate, m.threshold.shape[1], valid, margin=margin)
        tau = jnp.where(m.written > 0, tau, jnp.inf)
        nxt = jax.tree.map(lambda x: x[jnp.minimum(active + 1, k - 1)], m.params)
        return m.replace(threshold=m.threshold.at[active].set(tau), opt_state=optimizer.init(nxt),
                         written=jnp.zeros((), jnp.int32), fits=jnp.zeros((), jnp.int32),
                         ref_frozen=freeze_reference(m, active))

    return cond_per_seed(switch, switched, lambda m: m, memory)
