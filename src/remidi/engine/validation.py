"""Validation of a run before anything is written: the task itself (:func:`validate_task`: its
fields, and one abstractly traced reset and step), every key of :class:`UEDConfig` against its
allowed values and the task (one-line ConfigError naming the key), whether the network reads the
task's observations, and warnings about valid runs that would train degenerately."""

from __future__ import annotations

import dataclasses
import weakref

import jax
import jax.numpy as jnp
import numpy as np

from remidi.engine import buffer as buf
from remidi.engine import scores as sc
from remidi.engine.adversary import LevelBuffers
from remidi.engine.algorithms import ALGORITHMS, Algorithm, get_algorithm
from remidi.engine.config import POLICIES, UEDConfig, buffer_config, score_name
from remidi.engine.networks import flatten_obs, make_network
from remidi.engine.paired import ESTIMATORS, GENERATOR_NETWORKS, OVERLAP_REGRETS, LevelGenerator
from remidi.engine.train import example_observation, network_for
from remidi.envs.interface import UEDTask, UnderspecifiedEnv, tree_equal


_VALIDATED: weakref.WeakSet = weakref.WeakSet()  # tasks validate_task passed (UEDTask hashes by identity)
_STEP_READS_KEY: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # task -> _step_reads_its_key, once


def _user_error(err: Exception) -> str:
    """``Type: first line`` of an error raised by the user's code."""
    message = str(err).strip().splitlines()[0] if str(err).strip() else ""
    return f"{type(err).__name__}{': ' + message if message else ''}"


def _shapes(tree) -> str:
    """A pytree's leaves as ``dtype[shape]``, comma-separated (for messages); a leaf that is no
    array (a Python number) by its type's name."""
    def one(leaf):
        if not hasattr(leaf, "dtype") or not hasattr(leaf, "shape"):
            return f"{type(leaf).__name__}"
        return f"{leaf.dtype}{list(leaf.shape)}"
    return ", ".join(one(leaf) for leaf in jax.tree.leaves(tree))


def _check_action_count(task) -> None:
    """``task.num_actions`` against the environment's action space where it says (a gymnax
    ``Discrete(n)``, or a ``Box`` of continuous actions): an action the environment does not
    have would be taken silently (CartPole with 5 actions pushes 3, 5 and 7 times as hard)."""
    import math

    from remidi.errors import ConfigError

    try:
        space = task.env.action_space(task.params)
    except Exception:  # noqa: BLE001 (an environment without a usable action space: nothing to compare)
        return
    if task.continuous:
        shape = getattr(space, "shape", None)
        count = math.prod(shape) if isinstance(shape, tuple) and shape else None
    else:
        n = getattr(space, "n", None)
        count = int(n) if isinstance(n, (int, np.integer)) else None
    if count is not None and count != task.num_actions:
        kind = "continuous action dimensions" if task.continuous else "actions"
        raise ConfigError(f"task.num_actions: must be the environment's {count} {kind} (its action_space), got "
                          f"{task.num_actions}")


def _traced(field: str, what: str, fn, *args, hint: str = ""):
    """``jax.eval_shape(fn, *args)``; ConfigError ``task.FIELD: WHAT failed: Type: message`` (one
    line, ``hint`` appended) when the user's code raises."""
    from remidi.errors import ConfigError

    try:
        return jax.eval_shape(fn, *args)
    except Exception as err:  # noqa: BLE001 (the user's code: report its own error in one line)
        raise ConfigError(f"task.{field}: {what} failed: {_user_error(err)}{hint}") from None


def _is_scalar(x, kind: str) -> bool:
    """``x`` (a ShapeDtypeStruct) is a scalar of ``kind``: "float" or "bool"."""
    if getattr(x, "shape", None) != ():
        return False
    dtype = jnp.dtype(x.dtype)
    return dtype == jnp.bool_ if kind == "bool" else jnp.issubdtype(dtype, jnp.floating)


def _task_size(field: str, value) -> None:
    """ConfigError unless ``value`` is an integer ≥ 1 (a Python or NumPy integer, not a bool)."""
    from remidi.errors import ConfigError

    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{field}: must be an integer ≥ 1, got {value!r}")


def _reset_reads_its_key(task: UEDTask, rng, level) -> bool:
    """Whether the outputs of ``task.env.reset_to_level`` depend on its key, read from its traced
    program (JAX's dead-code elimination keeps the inputs an output uses; nothing is compiled). A
    task that claims ``deterministic_reset`` falsely would be replayed from one start per level
    and judged wrongly by ReMiDi's trackers. False where this JAX lacks the (internal) pass."""
    return _reads_key(lambda k, lv: task.env.reset_to_level(k, lv, task.params), rng, level)


def _reads_key(fn, key, *args, kept=lambda out: True) -> bool:
    """Whether the outputs of ``fn(key, *args)`` that ``kept`` (the output pytree -> a pytree of
    bools, or one bool for all) marks depend on ``key``: JAX's dead-code elimination of the traced
    program keeps the inputs those outputs use (nothing is compiled; arrays or ShapeDtypeStructs).
    False where this JAX lacks the (internal) pass, or ``fn`` does not trace this way."""
    try:
        from jax.interpreters import partial_eval as pe

        closed, out = jax.make_jaxpr(fn, return_shape=True)(key, *args)
        marks = kept(out)
        flags = [bool(m) for m in jax.tree.leaves(marks)] if not isinstance(marks, bool) else \
            [marks] * len(closed.jaxpr.outvars)
        _, used = pe.dce_jaxpr(closed.jaxpr, flags)
    except Exception:  # noqa: BLE001 (a JAX without this pass, or a function that traces only abstractly elsewhere)
        return False
    return bool(used[0])  # the key is the program's first input


def validate_task(task: UEDTask) -> None:
    """Raise ConfigError (one line naming the ``UEDTask`` field) for a task the engine cannot
    train: field types and ranges (``num_actions`` ≥ 1, ``max_episode_steps`` ≥ 1, the functions
    callable), then, traced abstractly (``jax.eval_shape``: nothing compiled or run), one sampled
    level, a reset to it and one step: the step's observation has the reset's shapes, its reward is
    a float scalar and its done a boolean scalar; the level tags are boolean scalars, the optimal
    returns float scalars, edited, easy and reseeded levels and a level the ``level_builder``
    builds from a whole design have the sampled level's shapes; every evaluation
    set is a batch of such levels (a leading level axis, the same on every leaf) that its
    environment resets to an observation of the training observation's shapes. Checked once per
    task object."""
    from remidi.errors import ConfigError

    if not isinstance(task, UEDTask):
        raise ConfigError(f"task: must be a remidi UEDTask, got a {type(task).__name__}")
    if task in _VALIDATED:
        return
    for key in ("num_actions", "max_episode_steps"):
        _task_size(f"task.{key}", getattr(task, key))
    for key in ("deterministic_reset", "continuous"):
        if not isinstance(getattr(task, key), bool):
            raise ConfigError(f"task.{key}: must be true or false, got {getattr(task, key)!r}")
    if not isinstance(task.env, UnderspecifiedEnv):
        raise ConfigError(f"task.env: must be a jaxued UnderspecifiedEnv, got a {type(task.env).__name__}")
    for key in ("sample_level", "level_tags"):
        if not callable(getattr(task, key)):
            raise ConfigError(f"task.{key}: must be a function, got {getattr(task, key)!r}")
    for key in ("optimal_return", "optimal_discounted_return", "solved", "expected_return", "mutate_level",
                "easy_level", "reseed_level"):
        if getattr(task, key) is not None and not callable(getattr(task, key)):
            raise ConfigError(f"task.{key}: must be a function or None, got {getattr(task, key)!r}")
    for key in ("eval_sets", "eval_envs"):
        value = getattr(task, key)
        if not isinstance(value, dict) or not all(isinstance(name, str) and name for name in value):
            raise ConfigError(f"task.{key}: must be a dict from set names (non-empty strings) to "
                              f"{'level batches' if key == 'eval_sets' else 'environments'}, got {value!r:.80}")
    for name, env in task.eval_envs.items():
        if name not in task.eval_sets:
            raise ConfigError(f"task.eval_envs: {name!r} is no evaluation set; allowed: {', '.join(task.eval_sets)}")
        if not isinstance(env, UnderspecifiedEnv):
            raise ConfigError(f"task.eval_envs: {name!r} must be a jaxued UnderspecifiedEnv, got a {type(env).__name__}")

    _check_action_count(task)

    rng = jax.random.PRNGKey(0)
    def first(k):
        lv = task.sample_level(k)
        return lv, task.env.reset_to_level(k, lv, task.params)

    try:  # the sampled level and the first observation (the message existing callers know)
        level, (obs, state) = jax.eval_shape(first, rng)
    except Exception as err:  # noqa: BLE001 (the user's environment: report its own error, once)
        raise ConfigError(f"task: sampling a level and resetting the environment to it failed: {_user_error(err)} "
                          f"(the environment must be a jaxued UnderspecifiedEnv and sample_level must return one of "
                          f"its levels)") from None
    if not jax.tree.leaves(obs):
        raise ConfigError("task.env: reset_to_level returned an observation without arrays")
    if task.deterministic_reset and _reset_reads_its_key(task, rng, level):
        raise ConfigError("task.deterministic_reset: true promises that env.reset_to_level ignores its key, but what "
                          "it returns depends on the key (traced); set it false (the reference tracker then "
                          "replays every start), or put the start's randomness into the level")
    action = (jax.ShapeDtypeStruct((task.num_actions,), jnp.float32) if task.continuous
              else jax.ShapeDtypeStruct((), jnp.int32))
    stepped = _traced("env", "a step of the environment", lambda k, s, a: task.env.step(k, s, a, task.params),
                      rng, state, action, hint=f" (from a level of sample_level: {_shapes(level)})")
    if not isinstance(stepped, tuple) or len(stepped) != 5:
        raise ConfigError("task.env: step must return (obs, state, reward, done, info)")
    next_obs, next_state, reward, done, _ = stepped
    if jax.tree.structure(next_obs) != jax.tree.structure(obs) or _shapes(next_obs) != _shapes(obs):
        raise ConfigError(f"task.env: a step's observation ({_shapes(next_obs)}) must have the reset's shapes "
                          f"({_shapes(obs)})")
    if jax.tree.structure(next_state) != jax.tree.structure(state) or _shapes(next_state) != _shapes(state):
        raise ConfigError("task.env: a step's state must have the shapes and dtypes of the reset's state")
    if not _is_scalar(reward, "float"):
        raise ConfigError(f"task.env: a step's reward must be a float scalar (f32[]) per environment, got "
                          f"{_shapes(reward)}")
    if not _is_scalar(done, "bool"):
        raise ConfigError(f"task.env: a step's done must be a boolean scalar (bool[]) per environment, got "
                          f"{_shapes(done)}")

    tags = _traced("level_tags", "tagging a sampled level", task.level_tags, level)
    if not isinstance(tags, dict) or not all(isinstance(n, str) and _is_scalar(v, "bool") for n, v in tags.items()):
        raise ConfigError(f"task.level_tags: must map a level to a dict of boolean scalars (bool[]), got {tags!r:.120}")
    if task.optimal_return is not None:
        value = _traced("optimal_return", "the optimal return of a sampled level", task.optimal_return, level)
        if not _is_scalar(value, "float"):
            raise ConfigError(f"task.optimal_return: must give a float scalar (f32[]) per level, got {_shapes(value)}")
    if task.optimal_discounted_return is not None:
        value = _traced("optimal_discounted_return", "the discounted optimal return of a sampled level",
                        lambda lv: task.optimal_discounted_return(lv, 0.99), level)
        if not _is_scalar(value, "float"):
            raise ConfigError(f"task.optimal_discounted_return: must give a float scalar (f32[]) per level, got "
                              f"{_shapes(value)}")
    if task.solved is not None:
        value = _traced("solved", "judging returns", task.solved, jax.ShapeDtypeStruct((3,), jnp.float32))
        if getattr(value, "shape", None) != (3,) or jnp.dtype(value.dtype) != jnp.bool_:
            raise ConfigError(f"task.solved: must map returns f32[N] to booleans bool[N], got {_shapes(value)} for N = 3")
    for key, fn in (("mutate_level", lambda k, lv: task.mutate_level(k, lv, 1)),
                    ("easy_level", lambda k, lv: task.easy_level(k)),
                    ("reseed_level", lambda k, lv: task.reseed_level(k, lv))):
        if getattr(task, key) is not None:
            made = _traced(key, "making a level", fn, rng, level)
            if jax.tree.structure(made) != jax.tree.structure(level) or _shapes(made) != _shapes(level):
                raise ConfigError(f"task.{key}: must return a level with the sampled level's shapes ({_shapes(level)}), "
                                  f"got {_shapes(made)}")
    builder = task.level_builder
    if builder is not None:
        for key in ("num_steps", "num_actions"):
            _task_size(f"task.level_builder.{key}", getattr(builder, key, None))
        made = _traced("level_builder", "building a level from a whole design",
                       lambda k: builder.build(k, jnp.zeros((builder.num_steps,), jnp.int32)), rng)
        if jax.tree.structure(made) != jax.tree.structure(level) or _shapes(made) != _shapes(level):
            raise ConfigError(f"task.level_builder: must build a level with the sampled level's shapes "
                              f"({_shapes(level)}), got {_shapes(made)}")

    level_leaves = jax.tree.leaves(level)
    for name, levels in task.eval_sets.items():
        leaves = jax.tree.leaves(levels)
        same_tree = jax.tree.structure(levels) == jax.tree.structure(level)
        counts = {np.shape(leaf)[0] if np.ndim(leaf) else None for leaf in leaves}
        if (not same_tree or any(np.ndim(a) != len(b.shape) + 1 for a, b in zip(leaves, level_leaves))
                or len(counts) != 1 or None in counts or 0 in counts):
            raise ConfigError(f"task.eval_sets: {name!r} must be a batch of levels, every leaf with the level's "
                              f"shape after one leading axis of the same length ≥ 1 (levels {_shapes(level)}; "
                              f"got {_shapes(levels) or 'no arrays'})")
        if any(not hasattr(leaf, "dtype") or jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key)
               for leaf in leaves):
            raise ConfigError(f"task.eval_sets: {name!r} must hold arrays (typed PRNG keys as jax.random.key_data), "
                              f"got {_shapes(levels)}")
        one = jax.tree.map(lambda x: np.asarray(x)[0], levels)
        if name not in task.eval_envs and _shapes(one) != _shapes(level):
            differ = [f"{jax.tree_util.keystr(path) or 'the level'} ({_shapes(a)} sampled, {_shapes(b)} here)"
                      for (path, a), b in zip(jax.tree_util.tree_flatten_with_path(level)[0], jax.tree.leaves(one))
                      if _shapes(a) != _shapes(b)]
            raise ConfigError(f"task.eval_sets: the levels of {name!r} must have the sampled level's dtypes and "
                              f"shapes; they differ in {'; '.join(differ)} (NumPy's int64 or float64: cast them, "
                              f"e.g. with jnp.asarray)")
        env = task.eval_envs.get(name, task.env)
        first = _traced("eval_sets", f"resetting to a level of {name!r}",
                        lambda k, lvs, env=env: env.reset_to_level(k, jax.tree.map(lambda x: x[0], lvs),
                                                                   task.params)[0],
                        rng, levels)
        if jax.tree.structure(first) != jax.tree.structure(obs) or _shapes(first) != _shapes(obs):
            raise ConfigError(f"task.eval_sets: {name!r}'s levels give observations {_shapes(first)}, but the network "
                              f"reads the training levels' {_shapes(obs)}")
    _VALIDATED.add(task)


def _observation_batch(task: UEDTask, flat: bool):
    """The task's first observation as a ``[1, 1, ...]`` batch (flattened to one vector if
    ``flat``), shapes only. Raises ConfigError, once, with the environment's own error when its
    level generator or reset fails (a network cannot be judged on an environment that does not run)."""
    from remidi.errors import ConfigError

    def first():
        obs = jax.tree.map(lambda x: x[None, None], example_observation(task)[0])
        return flatten_obs(obs) if flat else obs

    try:
        return jax.eval_shape(first)
    except Exception as err:  # the user's environment: report its own error, once
        message = str(err).strip().splitlines()[0] if str(err).strip() else ""
        raise ConfigError(f"task: sampling a level and resetting the environment to it failed: "
                          f"{type(err).__name__}{': ' + message if message else ''} (the environment must be a "
                          f"jaxued UnderspecifiedEnv and sample_level must return one of its levels)") from None


def _read_error(net, obs) -> Exception | None:
    """None if ``net`` can be initialised on the observation batch ``obs`` (traced abstractly),
    else the error it raised."""
    try:
        jax.eval_shape(lambda o: net.init(jax.random.PRNGKey(0), net.initialize_carry(1), o, jnp.ones((1, 1), bool)),
                       obs)
        return None
    except Exception as err:  # any failure to read the observation is the choice of network
        return err


def check_network_reads_observations(net, name: str, task: UEDTask, flat: bool = False) -> None:
    """Raise ConfigError unless ``net`` can be applied to the task's observations (flattened to
    one vector if ``flat``, as ``normalize_obs`` does; traced abstractly: nothing is compiled or
    run). The error names the networks that can; an environment that fails to produce an
    observation gets its own one-line error instead (:func:`_observation_batch`)."""
    from remidi.engine.networks import NETWORKS
    from remidi.errors import ConfigError

    obs = _observation_batch(task, flat)
    err = _read_error(net, obs)
    if err is None:
        return
    fits = [other for other in sorted(NETWORKS)
            if other != name and _read_error(make_network(other, task.num_actions, task.continuous), obs) is None]
    what = "this task's observations" + (" (flattened by normalize_obs)" if flat else "")
    raise ConfigError(f"network: {name} cannot read {what} ({type(err).__name__}); "
                      f"allowed: {', '.join(fits) or 'none of ' + ', '.join(sorted(NETWORKS))}")


def _step_reads_its_key(task: UEDTask) -> bool:
    """Whether the observation, state or end that ``task.env.step_env`` returns depend on its key
    (a step that draws its own randomness; a random reward or info alone does not change what the
    tracker compares), read from its traced program as :func:`_reset_reads_its_key` reads the
    reset's, at a sampled level's first state and a zero action. False where this JAX lacks the pass.
    Traced once per task."""
    if task not in _STEP_READS_KEY:
        _STEP_READS_KEY[task] = _trace_step_key_use(task)
    return _STEP_READS_KEY[task]


def _trace_step_key_use(task: UEDTask) -> bool:
    try:
        level = task.sample_level(jax.random.PRNGKey(0))
        _, state = task.env.reset_to_level(jax.random.PRNGKey(0), level, task.params)
    except Exception:  # noqa: BLE001 (validate_task reports a failing reset)
        return False
    action = jnp.zeros((task.num_actions,), jnp.float32) if task.continuous else jnp.zeros((), jnp.int32)

    def kept(out):  # the tracker reads observations and ends (and the state carries them on), not reward or info
        obs, nstate, reward, done, info = out
        return jax.tree.map(lambda _: True, (obs, nstate)), jax.tree.map(lambda _: False, reward), \
            jax.tree.map(lambda _: True, done), jax.tree.map(lambda _: False, info)

    return _reads_key(lambda k: task.env.step_env(k, state, action, task.params), jax.random.PRNGKey(1), kept=kept)


def run_warnings(cfg: UEDConfig, algo: str | Algorithm, task: UEDTask, check_step: bool = False) -> list[str]:
    """One-line warnings about a valid run that would train degenerately without saying so:

    * a score that needs finished episodes (``Score.needs_finished_episodes`` in the registry
      ``engine/scores.py``: every built-in one) on rollouts shorter than the task's episode limit: a
      level whose episode does not end inside the rollout scores −inf (``pvl``, ``maxmc``,
      ``learnability``: with every episode too long the buffer holds one level and replays only it)
      or by its partial return (``perfect_regret``, ``neg_return``: ``Score.unfinished`` says which);
    * ReMiDi on a task whose reset depends on its random key (two resets of one level with two keys
      give different first observations): the tracker assumes an episode is a function of the
      level and the actions, so it may judge identical levels distinguishable;
    * with ``check_step`` (a user's task: tracing a step costs seconds for Brax, whose steps are
      known to ignore their key), ReMiDi's exact tracker on a task whose step draws from its key:
      it steps each frozen level with the agent's own draws, so a prefix another draw of that level
      would give counts as distinguishable (the noisy domains of docs/results.md show the effect).
    """
    out = []
    algo = get_algorithm(algo)
    score = sc.SCORES[score_name(cfg, algo)]
    if algo.replays and score.needs_finished_episodes and cfg.num_steps < task.max_episode_steps:
        out.append(f"score {score.name} uses the episodes that end inside a rollout, but num_steps ({cfg.num_steps}) "
                   f"is shorter than an episode can last ({task.max_episode_steps}): levels whose episode does not "
                   f"end {score.unfinished}; raise num_steps or use another score")
    if algo.buffer_sequence and cfg.remidi.num_buffers > 1 and not task.deterministic_reset:
        level = task.sample_level(jax.random.PRNGKey(0))
        obs = [task.env.reset_to_level(jax.random.PRNGKey(k), level, task.params)[0] for k in (1, 2)]
        if not bool(tree_equal(obs[0], obs[1])):
            out.append("remidi: this task's reset depends on its random key (one level, two keys, two first "
                       "observations), but ReMiDi's tracker assumes an episode is a function of the level and the "
                       "actions; put the random seed into the level (UEDTask.deterministic_reset)")
    if check_step and algo.buffer_sequence and cfg.remidi.num_buffers > 1 \
            and cfg.remidi.tracker in ("prefix", "per_step") and _step_reads_its_key(task):
        out.append("remidi: this task's env.step_env draws from its random key, but ReMiDi's exact tracker steps "
                   "each frozen level with the agent's own draws, so a prefix that another draw of a frozen level "
                   "would give counts as distinguishable; draw the step's randomness from a seed the level holds "
                   "(remidi.envs.noisy does; UEDTask.reseed_level redraws it) or judge with remidi.tracker=belief "
                   "or simulated")
    return out


def rehearses(algo: Algorithm) -> bool:
    """``algo`` can take ``remidi.rehearsal``: a sequence of level buffers (ReMiDi, ReMiDi over ACCEL)."""
    return isinstance(algo.adversary, LevelBuffers) and algo.buffer_sequence


def validate_section(prefix: str, validate) -> None:
    """Call ``validate()`` (a nested config's validator, whose errors name its keys without the
    section) and raise its ConfigError with the keys' full dotted names (``prefix`` + key)."""
    from remidi.errors import ConfigError

    try:
        validate()
    except ConfigError as err:
        msg = str(err)
        raise ConfigError(msg if msg.startswith(prefix) else prefix + msg) from None


def task_refusal(algo: Algorithm, task: UEDTask) -> str | None:
    """Why ``task`` cannot run ``algo`` (None: it can): an algorithm that edits levels needs a
    level mutator, one that learns a level generator a level-building MDP."""
    if algo.edits and task.mutate_level is None:
        return f"{algo.name} edits levels, but this task has no level mutator (UEDTask.mutate_level)"
    if isinstance(algo.adversary, LevelGenerator) and task.level_builder is None:
        return (f"{algo.name} learns a level generator, but this task has no level-building MDP "
                f"(UEDTask.level_builder)")
    return None


def supported_algorithms(task: UEDTask) -> list[str]:
    """The registered algorithms ``task`` can run (:func:`task_refusal`), in their order."""
    return [name for name, algo in ALGORITHMS.items() if task_refusal(algo, task) is None]


def validate_ued_config(cfg: UEDConfig, algo: str | Algorithm, task: UEDTask) -> None:
    """Raise ConfigError (one line, naming the key and what is allowed) for an invalid run."""
    from remidi.engine.ppo import validate_ppo_config
    from remidi.engine.tracker import MODES
    from remidi.errors import ConfigError
    from remidi.errors import choice, positive_int, require

    algo = get_algorithm(algo)
    validate_task(task)
    for key in ("num_updates", "num_envs", "num_steps", "eval_every", "eval_attempts", "checkpoint_every"):
        positive_int(key, getattr(cfg, key))
    steps = cfg.num_updates * cfg.ppo.epochs * cfg.ppo.minibatches  # the optimiser's int32 step count
    if steps >= 2**31:
        raise ConfigError(f"num_updates: must keep num_updates × ppo.epochs × ppo.minibatches below 2^31 "
                          f"(the optimiser counts its steps in 32 bits), got {cfg.num_updates} × {cfg.ppo.epochs} × "
                          f"{cfg.ppo.minibatches} = {steps}; lower num_updates")
    if cfg.eval_every > cfg.num_updates:
        raise ConfigError(f"eval_every: must be ≤ num_updates ({cfg.num_updates}), got {cfg.eval_every}; "
                          f"lower eval_every or raise num_updates")
    require(isinstance(cfg.reseed, bool), "reseed", "true or false", cfg.reseed)
    require(not cfg.reseed or task.reseed_level is not None, "reseed", "false for a task without reseed_level (its "
            "levels carry no randomness of their own to draw afresh)", cfg.reseed)
    choice("score", cfg.score, sc.SCORES)
    score = sc.SCORES[score_name(cfg, algo)]
    for needed, what, has in (
            (score.needs_optimum, "the environment's optimal return, which this task does not provide "
                                  "(UEDTask.optimal_return)", task.optimal_return is not None),
            (score.needs_solved, "a solve criterion, which this task does not define (UEDTask.solved)",
             task.solved is not None)):
        if needed and not has:
            fits = [s.name for s in sc.SCORES.values() if not (s.needs_optimum and task.optimal_return is None)
                    and not (s.needs_solved and task.solved is None)]
            raise ConfigError(f"score: {score.name} needs {what}; allowed: {', '.join(fits)}")
    require(isinstance(cfg.discounted_regret, bool), "discounted_regret", "true or false", cfg.discounted_regret)
    if score.needs_optimum and cfg.discounted_regret and task.optimal_discounted_return is None:
        raise ConfigError(f"discounted_regret: this task gives no discounted optimal return "
                          f"(UEDTask.optimal_discounted_return), so {score.name} cannot use the discounted utility; "
                          f"allowed: false (undiscounted returns on both sides)")
    for key in ("hidden_size", "lstm_size"):
        require(isinstance(getattr(cfg, key), int) and getattr(cfg, key) >= 0, key,
                "an integer ≥ 0 (0: the network's default)", getattr(cfg, key))
    require(cfg.reward_scale > 0, "reward_scale", "> 0", cfg.reward_scale)
    # the network kind first (at its default sizes), then the sizes: a preset's hidden_size must not
    # hide that the network picked cannot read the task's observations
    check_network_reads_observations(network_for(dataclasses.replace(cfg, hidden_size=0, lstm_size=0), task),
                                     cfg.network, task, cfg.normalize_obs)
    network_for(cfg, task)  # ConfigError if the network has no layer for hidden_size / lstm_size
    r = cfg.remidi
    positive_int("remidi.num_buffers", r.num_buffers)
    positive_int("remidi.buffer_capacity", r.buffer_capacity)
    positive_int("remidi.steps_per_buffer", r.steps_per_buffer)
    require(isinstance(r.tracker_budget, int) and not isinstance(r.tracker_budget, bool) and r.tracker_budget >= 0,
            "remidi.tracker_budget", "an integer ≥ 0 (0: the reference tracker)", r.tracker_budget)
    choice("remidi.count", r.count, ("updates", "replays"))
    require(r.count == "updates" or algo.replays or not algo.buffer_sequence, "remidi.count", "updates with a "
            "learned generator (a generator never replays, so counting replays would never switch it)", r.count)
    if r.tracker not in MODES + ("belief", "simulated"):  # the exact tracker is "prefix" (the definition); name it so
        raise ConfigError(f"remidi.tracker: unknown value {r.tracker!r}; allowed: prefix (the exact tracker, the "
                          f"default), per_step (the authors' looser exact rule), belief (the learned belief model), "
                          f"simulated (the frozen levels simulated under fresh randomness, with a learnt noise model)")
    # the belief model's keys are checked whichever tracker runs: a bad value is a mistake either way
    require(0.0 <= r.belief_false_rate < 1.0, "remidi.belief_false_rate", "a number in [0, 1)", r.belief_false_rate)
    positive_int("remidi.belief_hidden", r.belief_hidden)
    positive_int("remidi.belief_calibration", r.belief_calibration)
    positive_int("remidi.belief_epochs", r.belief_epochs)
    require(r.belief_margin >= 0, "remidi.belief_margin", "≥ 0", r.belief_margin)
    require(r.belief_lr > 0, "remidi.belief_lr", "> 0", r.belief_lr)
    require(isinstance(r.belief_reference, bool), "remidi.belief_reference", "true or false", r.belief_reference)
    if r.tracker == "simulated":
        require(algo.replays or not algo.buffer_sequence, "remidi.tracker", "prefix, per_step or belief with a "
                "learned generator (the simulated model needs the adversary's levels: a buffer's)", r.tracker)
        require(task.deterministic_reset, "remidi.tracker", "prefix, per_step or belief for a task whose reset draws "
                "randomness (the simulated model follows the frozen levels from their fixed starts)", r.tracker)
    if r.tracker in ("belief", "simulated"):
        require(not r.belief_reference or algo.replays, "remidi.belief_reference", "false with a learned generator "
                "(the reference learns from the task generator's fresh levels, which a generator never plays)",
                r.belief_reference)
        require(not task.continuous, "remidi.tracker", "prefix or per_step for a task with continuous actions "
                "(the belief model reads discrete actions)", r.tracker)
        from remidi.engine import belief as bl

        obs = example_observation(task)[0]
        problem = bl.coding_problem(bl.coding_for(obs), obs)
        if problem is not None:
            raise ConfigError(f"remidi.tracker: {r.tracker} cannot read this task: {problem}; allowed here: prefix, "
                              f"per_step")
    choice("remidi.policy", r.policy, POLICIES)
    if r.policy == "combine":
        require(not cfg.normalize_obs, "remidi.policy", "masked with normalize_obs (the frozen policies would read "
                "observations normalised by statistics gathered after they were frozen)", r.policy)
        require(r.tracker in ("prefix", "belief"), "remidi.tracker", "prefix or belief with remidi.policy=combine (a "
                "policy per buffer acts where that buffer's levels produced, or its model explains, the whole prefix)",
                r.tracker)
    require(isinstance(r.rehearsal, (int, float)) and not isinstance(r.rehearsal, bool) and 0 <= r.rehearsal <= 1,
            "remidi.rehearsal", "a probability in [0, 1]", r.rehearsal)
    if r.rehearsal > 0:
        sequences = [a for a in ALGORITHMS if rehearses(ALGORITHMS[a])]
        if not rehearses(algo):
            raise ConfigError(f"remidi.rehearsal: {algo.name} has no sequence of level buffers to rehearse; allowed: 0, "
                              f"or a probability with --algo {' or '.join(sequences)}")
        require(r.policy == "masked", "remidi.policy", "masked with remidi.rehearsal (under combine the frozen "
                "policies act on the earlier buffers' levels, so the trained one never does)", r.policy)
    positive_int("accel.num_edits", cfg.accel.num_edits)
    require(isinstance(cfg.accel.easy_start, bool), "accel.easy_start", "true or false", cfg.accel.easy_start)
    if algo.edits and task.mutate_level is None:
        raise ConfigError(f"--algo: {task_refusal(algo, task)}; allowed: {', '.join(supported_algorithms(task))}")
    if algo.edits and cfg.accel.easy_start and task.easy_level is None:
        raise ConfigError("accel.easy_start: this task has no easy-level generator (UEDTask.easy_level); "
                          "allowed: false")
    if isinstance(algo.adversary, LevelGenerator):
        if task.level_builder is None:
            raise ConfigError(f"--algo: {task_refusal(algo, task)}; allowed: {', '.join(supported_algorithms(task))}")
        p = cfg.paired
        choice("paired.estimator", p.estimator, ESTIMATORS)
        if p.estimator == "perfect" and task.optimal_return is None:
            raise ConfigError("paired.estimator: perfect needs the task's optimal return (UEDTask.optimal_return); "
                              "allowed: paired, flexible")
        require(isinstance(p.clip_negative, bool), "paired.clip_negative", "true or false", p.clip_negative)
        choice("paired.generator_network", p.generator_network, GENERATOR_NETWORKS)
        positive_int("paired.generator_hidden", p.generator_hidden)
        require(p.generator_lr > 0, "paired.generator_lr", "> 0", p.generator_lr)
        require(p.generator_ent_coef >= 0, "paired.generator_ent_coef", "≥ 0", p.generator_ent_coef)
        choice("paired.overlap_regret", p.overlap_regret, OVERLAP_REGRETS)
        require(cfg.remidi.policy == "masked", "remidi.policy", "masked with a learned level generator (Combine "
                "over generators is not implemented)", cfg.remidi.policy)
    validate_section("ppo.", lambda: validate_ppo_config(cfg.ppo, cfg.num_envs))
    validate_section("buffer.", lambda: buf.validate_buffer_config(cfg.buffer))
    validate_section("buffer.", lambda: buf.validate_buffer_config(buffer_config(cfg, algo)))
    if algo.buffer_sequence:
        needed = (r.num_buffers - 1) * r.steps_per_buffer
        if needed >= cfg.num_updates:
            raise ConfigError(
                f"remidi.num_buffers: must be small enough that the last buffer gets updates, but "
                f"(num_buffers − 1) × steps_per_buffer = ({r.num_buffers} − 1) × {r.steps_per_buffer} = {needed} "
                f"is not below num_updates = {cfg.num_updates}; lower remidi.num_buffers or "
                f"remidi.steps_per_buffer, or raise num_updates")
