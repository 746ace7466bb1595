"""Exact-expectation UED on tabular one-step games: MMR-UED and ReMiDi (multi-policy form).

Players (both tabular actor-critics trained on *expected*, not sampled, quantities):

* the **agent** holds one softmax policy per observation, ``logits f32[O, A]``, and a critic
  ``value f32[O]``. Its reward for action ``a`` at observation ``o`` is minus the regret that
  action causes, weighted by the adversary's probability of each level behind ``o`` (not
  renormalised): ``q(o, a) = −Σ_{l: obs(l)=o} Λ(l)·regret(l, a)``. The entropy bonus acts on
  every observation's policy (coefficient × the entropy averaged over observations), so an
  observation the adversary stops sampling stops receiving learning signal but keeps being
  pulled towards uniform: the mechanism of regret stagnation.
* the **adversary** is a bandit over levels, ``logits f32[L]`` and a scalar critic; its reward
  for level ``l`` is the agent's expected regret on ``l``.

Each iteration runs ``adversary_updates`` adversary steps, then ``agent_updates`` agent steps.

**ReMiDi** (the paper's Algorithm 1, exact multi-policy form) keeps ``K`` (policy, adversary)
pairs. Stage ``k`` trains pair ``k``. The switching rule is explicit: after
``iters_per_adversary`` iterations the levels adversary ``k`` plays with probability
≥ ``support_threshold`` × its largest level probability form its support (:func:`support`);
their observations become *covered* and are from then on played by policy ``k`` (``Combine``:
the earliest policy whose adversary covered an observation acts there, the current policy
everywhere else). Adversary ``k+1`` may only choose
levels whose observation is not covered (a level whose observation was covered is in complete
overlap with an earlier adversary and is rejected). Policy ``k+1`` starts as a copy of policy
``k``. If no level is left, the stage does not advance. ``mmr`` is the case ``K = 1``.

Everything runs in one compiled program: ``lax.scan`` over logging blocks, ``fori_loop`` over
iterations, ``vmap`` over seeds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from remidi.solvers.onestep import OneStepGame

NEG = -1e9  # logit given to levels an adversary may not choose


@dataclass(frozen=True)
class TabularUEDConfig:
    """Hyper-parameters of exact tabular UED (defaults: the paper's, SPEC §5)."""

    iterations: int = field(default=3000, metadata={
        "help": "training iterations (each: adversary updates, then agent updates)"})
    adversary_updates: int = field(default=5, metadata={
        "help": "adversary (level distribution) gradient steps per iteration"})
    agent_updates: int = field(default=5, metadata={"help": "agent (policy) gradient steps per iteration"})
    policy_lr: float = field(default=0.01, metadata={"help": "learning rate of both players' logits"})
    value_lr: float = field(default=1.0, metadata={"help": "learning rate of the critics (SGD), in (0, 1]"})
    agent_entropy: float = field(default=0.1, metadata={
        "help": "agent's entropy bonus (coefficient × entropy averaged over observations)"})
    adversary_entropy: float = field(default=0.1, metadata={"help": "adversary's entropy bonus"})
    gamma: float = field(default=0.95, metadata={
        "help": "discount (one-step episodes: has no effect)"})
    optimizer: str = field(default="adam", metadata={
        "help": "optimizer of the logits: adam or sgd"})
    adam_b1: float = field(default=0.0, metadata={
        "help": "Adam's β1 (0: no momentum; 0.9 makes the players cycle)"})
    init_scale: float = field(default=0.5, metadata={
        "help": "std of the initial logits (the only source of seed variation)"})
    num_adversaries: int = field(default=3, metadata={
        "help": "remidi: number of (policy, adversary) pairs; mmr uses 1"})
    iters_per_adversary: int = field(default=1000, metadata={
        "help": "remidi: iterations before the next adversary takes over"})
    support_threshold: float = field(default=0.1, metadata={
        "help": "remidi: a level is in an adversary's support at ≥ this × its largest probability"})
    log_every: int = field(default=10, metadata={"help": "iterations between logged points"})


class GameArrays(NamedTuple):
    """JAX view of a :class:`OneStepGame`. ``obs_of`` i32[L], ``obs_level`` f32[O, L],
    ``action_regret`` f32[L, A]."""

    obs_of: jax.Array
    obs_level: jax.Array
    action_regret: jax.Array


class UEDState(NamedTuple):
    """State of one seed. K = number of (policy, adversary) pairs."""

    agent_logits: jax.Array  # f32[K, O, A]
    agent_value: jax.Array  # f32[K, O]
    agent_opt: optax.OptState  # stacked over K
    adv_logits: jax.Array  # f32[K, L]
    adv_value: jax.Array  # f32[K]
    adv_opt: optax.OptState  # stacked over K
    allowed: jax.Array  # bool[K, L], levels adversary k may choose
    owner: jax.Array  # i32[O], policy frozen on each observation; K = not covered yet
    stage: jax.Array  # i32[], index of the pair being trained


def game_arrays(game: OneStepGame) -> GameArrays:
    return GameArrays(
        obs_of=jnp.asarray(game.observation_index(), jnp.int32),
        obs_level=jnp.asarray(game.obs_level_matrix(), jnp.float32),
        action_regret=jnp.asarray(game.action_regret(), jnp.float32),
    )


# ---------------------------------------------------------------------------------- quantities
def level_regret(g: GameArrays, probs: jax.Array) -> jax.Array:
    """Expected regret per level, f32[L], of a policy ``probs`` f32[O, A]."""
    return jnp.sum(probs[g.obs_of] * g.action_regret, axis=-1)


def obs_regret(g: GameArrays, probs: jax.Array) -> jax.Array:
    """Greatest regret over the levels behind each observation, f32[O]."""
    per_level = level_regret(g, probs)
    return jnp.max(jnp.where(g.obs_level > 0, per_level[None, :], -jnp.inf), axis=1)


def agent_action_values(g: GameArrays, adv_probs: jax.Array) -> jax.Array:
    """The agent's expected reward ``q(o, a)``, f32[O, A], against adversary ``adv_probs`` f32[L]."""
    return -(g.obs_level * adv_probs[None, :]) @ g.action_regret


def adversary_probs(logits: jax.Array, allowed: jax.Array) -> jax.Array:
    """f32[L]: softmax over the allowed levels only."""
    return jax.nn.softmax(jnp.where(allowed, logits, NEG))


def support(probs: jax.Array, allowed: jax.Array, threshold: float) -> jax.Array:
    """bool[L]: the allowed levels played with probability ≥ ``threshold`` × the largest one.

    The rule is relative so that it does not depend on the number of levels: a support of m
    (roughly) equal levels is found whatever m (an absolute ``prob ≥ 0.1`` finds nothing once
    m > 10). For a softmax adversary it keeps the levels whose logit is within
    ``log(1/threshold)`` of the best one, and it is never empty while some level is allowed. In the
    paper's six-level game with the default hyper-parameters, the levels left out at a switch
    have about 0.02 × the largest probability and those kept at least 0.3 ×.
    """
    largest = jnp.max(jnp.where(allowed, probs, 0.0))
    return allowed & (probs >= threshold * largest)


def combined_probs(state: UEDState) -> jax.Array:
    """``Combine``: f32[O, A], the frozen policy on covered observations, the current one elsewhere."""
    acting = jnp.where(state.owner < state.stage, state.owner, state.stage)  # i32[O]
    logits = state.agent_logits[acting, jnp.arange(acting.shape[0])]
    return jax.nn.softmax(logits, axis=-1)


def _entropy(probs: jax.Array, axis=-1) -> jax.Array:
    return -jnp.sum(jnp.where(probs > 0, probs * jnp.log(jnp.where(probs > 0, probs, 1.0)), 0.0), axis=axis)


# ------------------------------------------------------------------------------------- updates
def _actor_critic_step(logits, value, opt_state, rewards, mask, entropy_coef, value_lr, opt):
    """One expected actor-critic step on independent softmax policies.

    ``logits`` f32[..., N] (one softmax per leading index), ``value`` f32[...] the critic,
    ``rewards`` f32[..., N] expected reward of each choice, ``mask`` bool[..., N] the choices
    that exist. Ascends ``Σ π(a)·(r(a) − V)`` (the expected policy gradient, summed over the
    softmaxes) plus ``entropy_coef`` times the entropy *averaged* over the softmaxes; the critic
    moves by ``value_lr`` towards the expected reward.
    """

    def loss(lg):
        probs = jax.nn.softmax(jnp.where(mask, lg, NEG), axis=-1)
        advantage = jax.lax.stop_gradient(rewards - value[..., None])
        surrogate = jnp.sum(probs * advantage, axis=-1)
        return -(jnp.sum(surrogate) + entropy_coef * jnp.mean(_entropy(probs))), probs

    grads, probs = jax.grad(loss, has_aux=True)(logits)
    updates, opt_state = opt.update(grads, opt_state, logits)
    expected = jnp.sum(probs * rewards, axis=-1)
    value = value + value_lr * (expected - value)
    return optax.apply_updates(logits, updates), value, opt_state


def _select(tree, k):
    return jax.tree.map(lambda x: x[k], tree)


def _put(tree, k, sub):
    return jax.tree.map(lambda x, s: x.at[k].set(s), tree, sub)


def adversary_step(state: UEDState, g: GameArrays, cfg: TabularUEDConfig, opt) -> UEDState:
    """One update of the current adversary against the (combined) agent."""
    k = state.stage
    regret = level_regret(g, combined_probs(state))
    logits, value, opt_state = _actor_critic_step(
        state.adv_logits[k], state.adv_value[k], _select(state.adv_opt, k),
        regret, state.allowed[k], cfg.adversary_entropy, cfg.value_lr, opt,
    )
    return state._replace(
        adv_logits=state.adv_logits.at[k].set(logits),
        adv_value=state.adv_value.at[k].set(value),
        adv_opt=_put(state.adv_opt, k, opt_state),
    )


def agent_step(state: UEDState, g: GameArrays, cfg: TabularUEDConfig, opt) -> UEDState:
    """One update of the current policy against the current adversary."""
    k = state.stage
    adv = adversary_probs(state.adv_logits[k], state.allowed[k])
    q = agent_action_values(g, adv)
    logits, value, opt_state = _actor_critic_step(
        state.agent_logits[k], state.agent_value[k], _select(state.agent_opt, k),
        q, jnp.ones_like(q, bool), cfg.agent_entropy, cfg.value_lr, opt,
    )
    return state._replace(
        agent_logits=state.agent_logits.at[k].set(logits),
        agent_value=state.agent_value.at[k].set(value),
        agent_opt=_put(state.agent_opt, k, opt_state),
    )


def maybe_switch(state: UEDState, g: GameArrays, cfg: TabularUEDConfig, iteration) -> UEDState:
    """The switching rule: at multiples of ``iters_per_adversary`` freeze the current pair.

    The current adversary's :func:`support` covers its levels' observations; those are owned by
    the current policy from now on. The next adversary may choose only levels on uncovered
    observations; with none left, nothing changes.
    """
    k = state.stage
    num_pairs = state.adv_logits.shape[0]
    chosen = support(adversary_probs(state.adv_logits[k], state.allowed[k]), state.allowed[k], cfg.support_threshold)
    newly_covered = (g.obs_level @ chosen.astype(jnp.float32)) > 0  # bool[O]
    owner = jnp.where((state.owner == num_pairs) & newly_covered, k, state.owner)
    covered = owner < num_pairs
    next_allowed = ~covered[g.obs_of]  # bool[L]
    due = (iteration > 0) & (iteration % cfg.iters_per_adversary == 0) & (k + 1 < num_pairs)
    switch = due & jnp.any(next_allowed)
    k_next = jnp.minimum(k + 1, num_pairs - 1)
    switched = state._replace(
        agent_logits=state.agent_logits.at[k_next].set(state.agent_logits[k]),
        agent_value=state.agent_value.at[k_next].set(state.agent_value[k]),
        allowed=state.allowed.at[k_next].set(next_allowed),
        owner=owner,
        stage=k_next,
    )
    return jax.tree.map(lambda new, old: jnp.where(switch, new, old), switched, state)


# ----------------------------------------------------------------------------------- training
def make_optimizer(cfg: TabularUEDConfig) -> optax.GradientTransformation:
    if cfg.optimizer == "adam":
        return optax.adam(cfg.policy_lr, b1=cfg.adam_b1)
    return optax.sgd(cfg.policy_lr)


def init_state(rng, g: GameArrays, cfg: TabularUEDConfig, num_pairs: int) -> UEDState:
    num_obs, num_actions = g.obs_level.shape[0], g.action_regret.shape[1]
    num_levels = g.obs_of.shape[0]
    opt = make_optimizer(cfg)
    k_agent, k_adv = jax.random.split(rng)
    agent_logits = cfg.init_scale * jax.random.normal(k_agent, (num_pairs, num_obs, num_actions))
    adv_logits = cfg.init_scale * jax.random.normal(k_adv, (num_pairs, num_levels))
    return UEDState(
        agent_logits=agent_logits,
        agent_value=jnp.zeros((num_pairs, num_obs)),
        agent_opt=jax.vmap(opt.init)(agent_logits),
        adv_logits=adv_logits,
        adv_value=jnp.zeros((num_pairs,)),
        adv_opt=jax.vmap(opt.init)(adv_logits),
        allowed=jnp.ones((num_pairs, num_levels), bool),
        owner=jnp.full((num_obs,), num_pairs, jnp.int32),
        stage=jnp.zeros((), jnp.int32),
    )


def metrics_of(state: UEDState, g: GameArrays) -> dict[str, jax.Array]:
    """Logged quantities of one seed: regret per observation f32[O], the current adversary's
    level probabilities f32[L], the combined policy f32[O, A] and the stage."""
    probs = combined_probs(state)
    k = state.stage
    return {
        "regret": obs_regret(g, probs),
        "adversary_prob": adversary_probs(state.adv_logits[k], state.allowed[k]),
        "policy": probs,
        "stage": state.stage,
    }


def train(seeds, game: OneStepGame, cfg: TabularUEDConfig, num_pairs: int):
    """Train every seed in ``seeds`` (ints; seed s uses ``PRNGKey(s)``, so its result does not
    depend on which other seeds run beside it) in one compiled program.

    Returns ``(final_states, history)``: ``history`` maps each metric of :func:`metrics_of` to an
    array with leading dims [S, num_logs + 1] (entry 0 is before training), plus ``steps``
    i32[num_logs + 1], the iteration count at each log.
    """
    g = game_arrays(game)
    opt = make_optimizer(cfg)
    num_logs = cfg.iterations // cfg.log_every

    def iteration(i, state):
        state = maybe_switch(state, g, cfg, i)
        state = jax.lax.fori_loop(0, cfg.adversary_updates, lambda _, s: adversary_step(s, g, cfg, opt), state)
        return jax.lax.fori_loop(0, cfg.agent_updates, lambda _, s: agent_step(s, g, cfg, opt), state)

    def block(state, b):
        start = b * cfg.log_every
        state = jax.lax.fori_loop(start, start + cfg.log_every, iteration, state)
        return state, metrics_of(state, g)

    def one_seed(key):
        state = init_state(key, g, cfg, num_pairs)
        first = metrics_of(state, g)
        state, hist = jax.lax.scan(block, state, jnp.arange(num_logs))
        hist = jax.tree.map(lambda f, h: jnp.concatenate([f[None], h]), first, hist)
        return state, hist

    keys = jax.vmap(jax.random.PRNGKey)(jnp.asarray(seeds, jnp.uint32))
    states, history = jax.jit(jax.vmap(one_seed))(keys)
    history = jax.tree.map(np.asarray, history)
    history["steps"] = np.arange(num_logs + 1) * cfg.log_every
    return states, history
