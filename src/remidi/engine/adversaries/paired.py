"""PAIRED's pieces (Dennis et al., 2020): the regret estimate a learned level generator is paid,
and the generator's sparse reward.

PAIRED trains three policies: a *generator* that builds levels action by action in the task's
level-building MDP (:mod:`remidi.envs.builder`), a *protagonist* (the agent UED trains) and an
*antagonist* that estimates what is achievable on each generated level. After both agents play a
level, the generator receives a regret estimate on its episode's last step, and nothing before:

* ``paired``: the antagonist's best episodic return minus the protagonist's mean (the original);
* ``flexible``: the better agent's best episodic return minus the other agent's mean, the
  better being the one with the higher best return, the protagonist on a tie (Jiang et al.,
  2021's "flexible PAIRED", as DCD computes it: neither agent is tied to a role);
* ``perfect``: the task's exact optimal return minus the protagonist's mean (the paper's
  "antagonist that is optimal on each level and does not learn"; needs ``UEDTask.optimal_return``).

All three are in undiscounted episodic returns (``optimal_return``, not the discounted optimum
that PLR's ``perfect_regret`` score uses under ``discounted_regret``), as the references pay
PAIRED's generator.

Negative regret (the protagonist beats the antagonist's best) is passed on as it is, unless
``clip_negative`` asks for 0: clipping hides from the generator which levels the antagonist has
not learned yet. All functions are pure, shapes in their docstrings.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
from flax import struct

from remidi.engine import learner as lrn
from remidi.engine.adversaries import level_buffer as buf
from remidi.engine.adversaries.base import Adversary, AdversaryState, Proposal, empty_buffers
from remidi.engine.adversaries.plr import buffer_contents, sequence_advance, sequence_frozen
from remidi.engine.config import buffer_config
from remidi.engine.core.networks import FeedForwardActorCritic, GeneratorLSTMActorCritic
from remidi.engine.core.ppo import create_train_state
from remidi.engine.learner import Batch, Policy, Stepping, compute_gae, nonfinite, ppo_update, rollout
from remidi.errors import ConfigError

ESTIMATORS = ("paired", "flexible", "perfect")


def regret_estimate(estimator: str, protagonist_mean, protagonist_best, antagonist_mean=None, antagonist_best=None,
                    optimal=None, clip_negative: bool = False) -> jax.Array:
    """f32[N]: the generator's regret estimate per level.

    ``protagonist_mean``, ``protagonist_best``: f32[N], the protagonist's mean and best episodic
    return on each level (``scores.episode_returns``: the partial return where no episode
    ended; a best of −inf, the train step's MaxMC record where no episode ended, reads as that
    partial return, the mean, as the antagonist's is read); ``antagonist_mean``,
    ``antagonist_best``: the antagonist's (``paired``, ``flexible``); ``optimal``: f32[N], the
    task's optimal return (``perfect``). ``estimator`` and ``clip_negative`` are static."""
    protagonist_best = jnp.where(jnp.isneginf(protagonist_best), protagonist_mean, protagonist_best)
    if estimator == "paired":
        regret = antagonist_best - protagonist_mean
    elif estimator == "flexible":
        antagonist_better = antagonist_best > protagonist_best
        regret = jnp.where(antagonist_better, antagonist_best - protagonist_mean, protagonist_best - antagonist_mean)
    elif estimator == "perfect":
        regret = optimal - protagonist_mean
    else:
        raise ValueError(f"regret estimator must be one of {ESTIMATORS}, got {estimator!r}")
    return jnp.maximum(regret, 0.0) if clip_negative else regret


def regret_by_tag(tags, regret, antagonist_luck, optimal, protagonist_mean) -> dict[str, jax.Array]:
    """Where the estimate's regret comes from, per tag of the generated levels (``tags``: the task's
    ``level_tags`` of the N levels, ``{name: bool[N]}``) and for the levels with no tag
    (``untagged``); NaN where no generated level has it:

    * ``paired/regret/<tag>``: the estimate the generator was paid (before overlap handling);
    * ``paired/antagonist_luck/<tag>``: the antagonist's best episodic return minus its mean, the
      part of ``paired``'s estimate that a lucky episode adds (a guessed hidden lever);
    * ``paired/exact_regret/<tag>``: the task's optimal return minus the protagonist's mean, where
      the task has an optimum (what ``perfect`` pays), to read the estimate against."""
    groups = dict(tags)
    groups["untagged"] = ~jnp.any(jnp.stack(list(tags.values())), axis=0) if tags else jnp.ones_like(regret, bool)
    values = {"regret": regret, "antagonist_luck": antagonist_luck}
    if optimal is not None:
        values["exact_regret"] = optimal - protagonist_mean
    out = {}
    for group, members in groups.items():
        count = jnp.sum(members)
        for name, x in values.items():
            out[f"paired/{name}/{group}"] = jnp.where(count > 0, jnp.sum(jnp.where(members, x, 0.0)) / count, jnp.nan)
    return out


def generator_rewards(regret: jax.Array, num_steps: int) -> tuple[jax.Array, jax.Array]:
    """The generator's episode as a reward signal: ``(rewards f32[T, N], dones bool[T, N])`` with
    T = ``num_steps`` (the level-building MDP's budget), the regret ``f32[N]`` on the last step and
    0 before, and the episode ending there, so GAE never bootstraps past the generator's episode
    (:func:`remidi.engine.learner.compute_gae` gives ``reward − V`` at its last step whatever value
    follows)."""
    n = regret.shape[0]
    last = jnp.arange(num_steps)[:, None] == num_steps - 1
    rewards = jnp.where(last, regret[None, :], 0.0).astype(jnp.float32)
    return rewards, jnp.broadcast_to(last, (num_steps, n))


# ------------------------------------------------------------------------------- the adversary
GENERATOR_NETWORKS = ("mlp", "reference")


def generator_net(setup):
    """The generator's actor-critic, one logit per design action; ``paired.generator_network``:

    * ``mlp`` (default, sized for a CPU): an MLP over its flattened observation (design, time
      step, noise), ``paired.generator_hidden`` units per trunk layer;
    * ``reference``: the reference libraries' adversary (JaxUED, DCD): a 128-channel conv over a
      maze design, an embedded time step and the noise into a 256-unit LSTM
      (:class:`remidi.engine.core.networks.GeneratorLSTMActorCritic`)."""
    builder, p = setup.task.level_builder, setup.cfg.paired
    if p.generator_network == "reference":
        return GeneratorLSTMActorCritic(num_actions=builder.num_actions)
    return FeedForwardActorCritic(num_actions=builder.num_actions, hidden=(p.generator_hidden, p.generator_hidden))


def generator_ppo(setup):
    """The generator's PPO settings: the run's, with ``paired.generator_lr`` and
    ``paired.generator_ent_coef``."""
    p = setup.cfg.paired
    return dataclasses.replace(setup.cfg.ppo, lr=p.generator_lr, ent_coef=p.generator_ent_coef)


@struct.dataclass
class GeneratorState(AdversaryState):
    """:class:`~remidi.engine.adversaries.base.AdversaryState` (the buffers: a generator
    sequence's reservoirs) and PAIRED's learners: the ``generator``'s and the ``antagonist``'s
    TrainState; ``next_generators``: a sequence's fresh generators of the later buffers (leaves
    [K−1, ...]; None for one generator)."""

    generator: object = None
    antagonist: object = None
    next_generators: object = None


@dataclass(frozen=True)
class LevelGenerator(Adversary):
    """PAIRED's adversary: a generator policy builds the N levels of each update in the task's
    level-building MDP (one episode of ``level_builder.num_steps`` design actions each); the
    protagonist (the agent) trains on all of them; then an antagonist, an agent of the same
    network with its own parameters, plays them once and learns by PPO, and the generator is paid
    :func:`regret_estimate` on its last step and learns by PPO (its own network and settings:
    :func:`generator_net`, :func:`generator_ppo`). All three learn in the same jitted step."""

    trains_on_fresh: bool = True

    def init(self, setup, example_level, example_obs, rng) -> GeneratorState:
        """The buffers, a fresh generator and antagonist from ``rng`` (folded, never split)."""
        base = super().init(setup, example_level, example_obs, rng)
        return GeneratorState(buffers=empty_buffers(setup, example_level), active=base.active, count=base.count,
                              **self._learners(setup, example_obs, rng))

    def _learners(self, setup, example_obs, rng, antagonist: bool = True) -> dict:
        """A fresh generator (and antagonist) from ``rng`` (folded, never split)."""
        builder = setup.task.level_builder
        gen_obs, _ = builder.reset_to_level(jax.random.PRNGKey(0), None, None)
        cfg = setup.cfg
        out = {"generator": create_train_state(jax.random.fold_in(rng, 11), generator_net(setup), gen_obs,
                                               cfg.num_envs, generator_ppo(setup))}
        if antagonist:
            out["antagonist"] = create_train_state(jax.random.fold_in(rng, 12), setup.net, example_obs, cfg.num_envs,
                                                   cfg.ppo)
        return out

    def propose(self, setup, runner, fresh, k_branch, k_levels, k_sample) -> Proposal:
        """One episode of the generator per env; the levels are what its actions built."""
        state = runner.adversary
        builder, n = setup.task.level_builder, setup.cfg.num_envs
        net = generator_net(setup)
        traj, last_value = rollout(k_levels, Stepping(builder, None),
                                   Policy(net.apply, state.generator.params, net.initialize_carry(n)),
                                   jnp.zeros((n,), jnp.int32), builder.num_steps)
        # the rollout's reset keys (as rollout splits them): the builder's episode keys
        reset_keys = jax.random.split(jax.random.split(k_levels)[1], n)
        levels = jax.vmap(builder.build)(reset_keys, traj.action.T)
        replay = jnp.asarray(False)
        return Proposal(replay=replay, levels=levels, buffer=buf.select_buffer(state.buffers, state.active),
                        slots=None, train=jnp.asarray(True), generated=(traj, last_value),
                        nonfinite=nonfinite(traj, "generator"))

    def update(self, setup, runner, proposal: Proposal, outcome, rng):
        """The antagonist plays the levels and learns (the agent's rollout and masked PPO, with
        its parameters and nothing frozen); the generator is paid and learns."""
        cfg, task, state = setup.cfg, setup.task, runner.adversary
        n = cfg.num_envs
        k_roll, k_ant, k_gen = (jax.random.fold_in(rng, i) for i in (21, 22, 23))
        # under normalize_obs the antagonist reads observations normalised by the protagonist's
        # running statistics (both play these levels), which only the protagonist's rollout updates
        as_antagonist = runner.learner.replace(train_state=state.antagonist)
        played = lrn.collect(setup, as_antagonist, k_roll, proposal.levels, None)
        traj, ant_mean, ant_best = played.traj, played.mean_return, played.best_return
        antagonist = lrn.train(setup, as_antagonist, True, k_ant, played)[0].train_state
        optimal = jax.vmap(task.optimal_return)(proposal.levels) if task.optimal_return is not None else None
        p = cfg.paired
        mean_return = outcome.collection.mean_return
        regret = regret_estimate(p.estimator, mean_return, outcome.collection.best_return, ant_mean, ant_best, optimal,
                                 p.clip_negative)
        paid = self._pay(setup, regret, outcome.overlap)
        # the generator: paid on its last step, no bootstrap past its episode
        gen_traj, gen_last = proposal.generated
        net = generator_net(setup)
        # in the units the agents learn in (reward × reward_scale: Brax's ±10000 rewards ÷ 10), as
        # PPO's value loss would otherwise dwarf its policy loss; the metrics stay unscaled
        rewards, dones = generator_rewards(paid * cfg.reward_scale, gen_traj.reward.shape[0])
        g_adv, g_targets = compute_gae(rewards, gen_traj.value, dones, gen_last, cfg.ppo.gamma, cfg.ppo.gae_lambda)
        generator, g_metrics = ppo_update(state.generator, net.initialize_carry(n), Batch(
            obs=gen_traj.obs, reset=gen_traj.reset, actions=gen_traj.action, log_probs=gen_traj.log_prob,
            values=gen_traj.value, advantages=g_adv, targets=g_targets, mask=jnp.ones_like(dones)),
            k_gen, generator_ppo(setup), net.apply)
        metrics = {"paired/regret": jnp.mean(regret), "paired/antagonist_return": jnp.mean(ant_mean),
                   "paired/generator_entropy": g_metrics["entropy"].astype(jnp.float32),
                   **nonfinite(traj, "antagonist")}
        tags = jax.vmap(task.level_tags)(proposal.levels)  # {name: bool[N]}
        for name, t in tags.items():
            metrics[f"generated/{name}"] = jnp.sum(jnp.where(t, 1.0, 0.0)) / n
        metrics.update(regret_by_tag(tags, regret, ant_best - ant_mean, optimal, mean_return))
        state = state.replace(generator=generator, antagonist=antagonist)
        state, inserted = self._keep(setup, state, proposal, jax.random.fold_in(rng, 24))
        return state, inserted, metrics

    def _pay(self, setup, regret, overlap):
        """f32[N]: what the generator is paid for each level: its regret estimate."""
        return regret

    def _keep(self, setup, state, proposal: Proposal, rng):
        """``(state, inserted bool[N])``: what the adversary keeps of the levels: nothing."""
        return state, jnp.zeros((setup.cfg.num_envs,), bool)


OVERLAP_REGRETS = ("lowest", "zero")


@dataclass(frozen=True)
class GeneratorSequence(LevelGenerator):
    """ReMiDi over PAIRED (Algorithm 1 with generators as its adversaries): a sequence of
    ``remidi.num_buffers`` generators, each used for ``remidi.steps_per_buffer`` updates, then
    frozen, and a fresh one started (the last stays); one protagonist, trained only on the steps
    no frozen generator's support explains (the loss mask), and one antagonist for all of them.

    A generator's empirical support is a reservoir of the levels it generated: the active
    buffer of ``runner.buffers`` (``remidi.buffer_capacity`` levels), filled by reservoir
    sampling (every generated level gets an i.i.d. uniform key and the reservoir keeps the levels
    with the highest keys: without ``buffer.duplicate_check`` a uniform sample of all it
    generated; with it, on in every preset, a level generated again keeps the highest of its keys
    in its one entry instead of taking a second slot, so the reservoir holds the distinct levels
    whose best draw is highest: a level generated m times is kept as if any of its m copies had
    been, a sample weighted by how often the generator makes it). The frozen generators'
    reservoirs are the tracker's frozen levels. A generated level whose rollout a frozen level
    explains at every step (a complete overlap) gives the protagonist no gradient (every step is
    masked) and pays the generator ``paired.overlap_regret`` (``lowest``: the lowest regret
    estimate of the update's levels; ``zero``), so later generators learn to leave earlier
    supports.

    With a learned tracker (:mod:`remidi.engine.trackers.belief`) a model of each generator's
    trajectories judges instead of its reservoir (the paper's appendix sketch, P(h | Λᵢ) learnt
    with Λᵢ: every update's rollout shows the active generator's levels, :meth:`own_levels`); the
    reservoir is still kept, for the audit against the exact tracker.

    Where it approximates Algorithm 1: the support is a finite sample of the generator's
    distribution (a level the generator rarely makes may be missing from it, and a later level
    identical to it is then not recognised); the generator is a policy trained by PPO, not an
    exact best response; the antagonist's best return estimates the optimum (``perfect`` uses the
    exact one); one masked protagonist stands for the per-adversary policies and Combine."""

    buffer_sequence: bool = True

    def __post_init__(self):
        super().__post_init__()
        if not self.buffer_sequence:
            raise ConfigError("adversary: GeneratorSequence is a sequence of generators (without it, it is PAIRED's "
                              "LevelGenerator); allowed: buffer_sequence=True")

    def frozen(self, setup, runner, proposal: Proposal | None = None):
        return sequence_frozen(setup, runner, proposal)

    def own_levels(self, proposal: Proposal) -> jax.Array:
        """Every update plays the active generator's levels: a learned tracker's model learns from each."""
        return jnp.asarray(True)

    def metrics(self, setup, runner) -> dict:
        """What each generator's reservoir holds (``buffer_fraction/<tag>/b<k>``)."""
        return buffer_contents(setup, runner.adversary)

    def _pay(self, setup, regret, overlap):
        low = jnp.min(regret) if setup.cfg.paired.overlap_regret == "lowest" else 0.0
        return jnp.where(overlap, low, regret)

    def _keep(self, setup, state, proposal: Proposal, rng):
        bcfg = dataclasses.replace(buffer_config(setup.cfg, setup.algo), staleness_coef=0.0, prioritization="rank")
        active = buf.select_buffer(state.buffers, state.active)
        keys = jax.random.uniform(rng, (setup.cfg.num_envs,))
        new_buf, inserted, _ = buf.insert_batch(active, bcfg, proposal.levels, keys,
                                                {"max_return": jnp.zeros((setup.cfg.num_envs,))}, keep_higher=True)
        return state.replace(buffers=buf.replace_buffer(state.buffers, state.active, new_buf)), inserted

    def init(self, setup, example_level, example_obs, rng) -> GeneratorState:
        """The first generator and the antagonist, and the fresh generators of the later buffers
        (initialised here, once: initialising in the step would put batched QR decompositions,
        orthogonal initialisers, into the vmapped program, which hangs jaxlib's CPU runtime)."""
        state = super().init(setup, example_level, example_obs, rng)
        later = [self._learners(setup, example_obs, jax.random.fold_in(rng, 100 + k), antagonist=False)["generator"]
                 for k in range(1, setup.cfg.remidi.num_buffers)]
        return state.replace(next_generators=jax.tree.map(
            lambda *xs: jnp.stack(xs), *[g.replace(apply_fn=None, tx=None) for g in later]) if later else None)

    def advance(self, setup, runner, proposal: Proposal, outcome):
        """After ``remidi.steps_per_buffer`` updates: freeze the generator's reservoir, move to the
        next and start a fresh generator (new parameters and optimiser state); the tracker and the
        policy freeze at the same switch (:func:`~remidi.engine.adversaries.plr.sequence_advance`)."""
        counted, _ = super().advance(setup, runner, proposal, outcome)
        runner, metrics = sequence_advance(setup, counted, counted.adversary, proposal, outcome)
        state, before = runner.adversary, counted.adversary
        if state.next_generators is None:  # remidi.num_buffers=1: one generator, never switched
            return runner, metrics
        switch = state.active != before.active
        fresh = jax.tree.map(lambda x: x[jnp.minimum(before.active, x.shape[0] - 1)], state.next_generators)
        old = state.generator
        pick = lambda f, g: jax.tree.map(lambda a, b: jnp.where(switch, a, b), f, g)  # noqa: E731
        generator = old.replace(params=pick(fresh.params, old.params), opt_state=pick(fresh.opt_state, old.opt_state),
                                step=pick(fresh.step, old.step))
        return runner.replace(adversary=state.replace(generator=generator)), metrics
