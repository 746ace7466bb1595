# Usage: python docs/notes/belief_probe.py blindfold-noisy|tmaze [FIT_STEPS=300] [reseed|same] [FALSE_RATE=0.05]   (minutes on a 2-core CPU)
"""Constructed probe of the belief tracker on mazes, with and without the generator reference.

A frozen buffer concentrated on irreducible levels (90 % blind / T-maze, as PLR⊥'s buffer is at
the cpu preset), a random policy; the model fits rollouts of the buffer's levels, the reference
fits rollouts of the task generator's fresh levels, thresholds calibrated on held-out buffer
rollouts (the ratio's for the ratio). Then fresh generator levels are judged by kind: the share
of steps explained and of episodes explained at every step (complete overlap: rejected), beside
the exact tracker's (for the deterministic T-maze)."""
import sys
import jax, jax.numpy as jnp, numpy as np
from remidi.engine.trackers import belief as bl
from remidi.engine.trackers import belief_model as bm
from remidi.engine.trackers import calibration as cal
from remidi.engine.learner import Policy, Stepping, rollout
from remidi.engine.trackers.base import Frozen
from remidi.engine.trackers.exact import ExactTracker
from remidi.envs.maze import maze_task
from remidi.envs.noisy import noisy_blindfold_task

kind = sys.argv[1]  # blindfold-noisy | tmaze
task = noisy_blindfold_task(0.5, 25) if kind == "blindfold-noisy" else maze_task("tmaze", 0.5, 25)
tag = "blind" if kind == "blindfold-noisy" else "tmaze"
A = task.num_actions
T, N, C = 32, 256, 32
STEPS, HIDDEN = int(sys.argv[2]) if len(sys.argv) > 2 else 300, 64

def policy(variables, carry, obs, reset):
    return carry, (jnp.zeros(reset.shape + (A,)), jnp.zeros(reset.shape))

def roll(levels, key, frozen=None):
    traj, _ = rollout(key, Stepping(task.env, task.params, task.deterministic_reset), Policy(policy, {}, jnp.zeros(1)),
                      levels, T, frozen)
    return traj

pool = jax.vmap(task.sample_level)(jax.random.split(jax.random.PRNGKey(0), 4000))
irr = np.asarray(jax.vmap(lambda l: task.level_tags(l)[tag])(pool))
idx = np.concatenate([np.nonzero(irr)[0][:int(0.9 * C)], np.nonzero(~irr)[0][:C - int(0.9 * C)]])
buffer = jax.tree.map(lambda x: x[idx], pool)
RESEED = len(sys.argv) > 3 and sys.argv[3] == "reseed"
ALPHA = float(sys.argv[4]) if len(sys.argv) > 4 else 0.05  # the false-distinguishable rate
def from_buffer(key, n):
    k1, k2 = jax.random.split(key)
    levels = jax.tree.map(lambda x: x[jax.random.randint(k1, (n,), 0, C)], buffer)
    if RESEED:  # the level's randomness drawn afresh each time (a stochastic environment)
        from remidi.envs.noisy import draw_seed
        levels = levels.replace(seed=jax.vmap(draw_seed)(jax.random.split(k2, n)))
    return levels
fresh = jax.vmap(task.sample_level)(jax.random.split(jax.random.PRNGKey(7), N))

example, _ = task.env.reset_to_level(jax.random.PRNGKey(0), jax.tree.map(lambda x: x[0], buffer), task.params)
model = bm.BeliefModel(bm.coding_for(example), num_actions=A, hidden=HIDDEN)
opt = bm.make_optimizer(1e-2)

@jax.jit
def fit(params, obs, action, reset):
    params, _, losses = bm.fit_steps(model, opt, params, opt.init(params), obs, action, reset, STEPS)
    return params, losses

data = roll(from_buffer(jax.random.PRNGKey(1), N), jax.random.PRNGKey(2))
params, losses = fit(model.init(jax.random.PRNGKey(3)), data.obs, data.action, data.reset)
gen = roll(jax.vmap(task.sample_level)(jax.random.split(jax.random.PRNGKey(11), N)), jax.random.PRNGKey(12))
ref, rlosses = fit(model.init(jax.random.PRNGKey(13)), gen.obs, gen.action, gen.reset)
print(f"model loss {float(losses[0]):.1f} -> {float(losses[-1]):.1f}; reference {float(rlosses[0]):.1f} -> "
      f"{float(rlosses[-1]):.1f}; uniform {-bl.uniform_score(model):.1f} nats per step")

held = roll(from_buffer(jax.random.PRNGKey(4), N), jax.random.PRNGKey(5))
lengths = bm.prefix_lengths(held.reset)
L = cal.num_length_buckets(T)
exact = Frozen(levels=buffer, valid=jnp.ones((C,), bool), tracker=ExactTracker())
ex = roll(fresh, jax.random.PRNGKey(8), exact)
fresh_irr = np.asarray(jax.vmap(lambda l: task.level_tags(l)[tag])(fresh))

def report(name, traj):
    ind = np.asarray(traj.indist)  # [T, N]
    # an episode explained at every step: the first episode of each env (up to its end or T)
    first = np.cumsum(np.asarray(traj.reset), axis=0) <= 1
    whole = np.all(ind | ~first, axis=0)
    for lab, m in (("irreducible", fresh_irr), ("ordinary", ~fresh_irr)):
        print(f"  {name:10s} {lab:11s}: steps explained {ind[:, m].mean():.2f}, first episodes explained "
              f"throughout {whole[m].mean():.2f}")

report("exact", ex)
for use_ref in (False, True):
    ll = bm.step_logliks(model, params, held.obs, held.action, held.reset)
    if use_ref:
        ll = ll - bm.step_logliks(model, ref, held.obs, held.action, held.reset)
    scores = bm.prefix_scores(ll, held.reset)
    tau = cal.calibrate_monotone(scores[None], lengths[None], ALPHA, L)
    fb = bl.FrozenBeliefs(params=jax.tree.map(lambda x: x[None], params), threshold=tau[None],
                          valid=jnp.ones((1,), bool), ref=jax.tree.map(lambda x: x[None], ref) if use_ref else None)
    tr = roll(fresh, jax.random.PRNGKey(8), Frozen(levels=None, valid=None, tracker=bl.BeliefTracker(model), belief=fb))
    agree = float(np.mean(np.asarray(tr.indist) == np.asarray(ex.indist)))
    print(f"belief {'ratio' if use_ref else 'plain'}: thresholds {np.round(np.asarray(tau), 1)}; agreement with exact {agree:.2f}")
    report("ratio" if use_ref else "plain", tr)
