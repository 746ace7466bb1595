"""Checks of a task before a run: its fields, one abstractly traced reset and step
(:func:`validate_task`), whether a network reads its observations
(:func:`check_network_reads_observations`) and whether its step draws from its key
(:func:`step_reads_its_key`). One-line ConfigErrors naming the field."""

from __future__ import annotations

import weakref

import jax
import jax.numpy as jnp
import numpy as np

from remidi.engine.core.distributions import for_task
from remidi.engine.core.networks import (NETWORKS, describe_observation, flatten_obs, make_network,
                                         observation_problem, reads)
from remidi.engine.setup import example_observation
from remidi.envs import actions as acts
from remidi.envs.interface import UEDTask, UnderspecifiedEnv
from remidi.errors import ConfigError, a_type


_VALIDATED: weakref.WeakSet = weakref.WeakSet()  # tasks validate_task passed (UEDTask hashes by identity)
_STEP_READS_KEY: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()  # task -> _step_reads_its_key, once


def _user_error(err: Exception) -> str:
    """``Type: first line`` of an error raised by the user's code."""
    message = str(err).strip().splitlines()[0] if str(err).strip() else ""
    return f"{type(err).__name__}{': ' + message if message else ''}"


def _shapes(tree, most: int | None = None) -> str:
    """A pytree's leaves as ``dtype[shape]`` (non-arrays by type name), comma-separated; the first
    ``most`` (None: all) and how many more."""
    leaves = [_leaf(leaf) for leaf in jax.tree.leaves(tree)]
    more = len(leaves) - most if most is not None and len(leaves) > most else 0
    return ", ".join(leaves[:len(leaves) - more]) + (f" and {more} more" if more else "")


def _leaf(leaf) -> str:
    """``dtype[shape]`` of an array leaf, else the type's name."""
    if not hasattr(leaf, "shape") or not hasattr(leaf, "dtype"):
        return type(leaf).__name__
    return f"{leaf.dtype}{list(leaf.shape)}"


def _difference(expected, given, what: str = "expected") -> str | None:
    """The first leaf where ``given`` differs from ``expected`` in path, shape or dtype (``".path (f32[3]
    WHAT, i32[3] here)"``) and how many more; None where they agree."""
    def table(tree):
        return {jax.tree_util.keystr(path): _leaf(x) for path, x in jax.tree_util.tree_flatten_with_path(tree)[0]}

    want, got = table(expected), table(given)
    differ = [f"{path or 'the whole'} ({want.get(path, 'no leaf')} {what}, {got.get(path, 'no leaf')} here)"
              for path in dict.fromkeys([*want, *got]) if want.get(path) != got.get(path)]
    if not differ:
        return None if jax.tree.structure(expected) == jax.tree.structure(given) else \
            f"the containers differ ({jax.tree.structure(given)} here)"
    return differ[0] + (f" and {len(differ) - 1} more" if len(differ) > 1 else "")


def _batch_problem(level, levels) -> str | None:
    """The first leaf where ``levels`` is no batch of levels like ``level`` (one leading axis of a
    common length ≥ 1, then the leaf's rank) and how many more; None where it is."""
    paths = jax.tree_util.keystr
    rank = {paths(p): len(x.shape) for p, x in jax.tree_util.tree_flatten_with_path(level)[0]}
    got = {paths(p): np.shape(x) for p, x in jax.tree_util.tree_flatten_with_path(levels)[0]}
    if not got:
        return "no arrays"
    count = next(iter(got.values()))[:1] or (0,)
    differ = [f"{path or 'the whole'} ({'no leaf' if path not in rank else f'[{count[0]}, rank {rank[path]}]'} "
              f"expected, {list(got[path]) if path in got else 'no leaf'} here)"
              for path in dict.fromkeys([*rank, *got])
              if path not in rank or path not in got or len(got[path]) != rank[path] + 1 or got[path][:1] != count
              or count == (0,)]
    if not differ:
        return None if jax.tree.structure(levels) == jax.tree.structure(level) else \
            f"the containers differ ({jax.tree.structure(levels)} here)"
    return differ[0] + (f" and {len(differ) - 1} more" if len(differ) > 1 else "")


def _check_actions(task) -> None:
    """Check the task's action declaration, and the space against the env's ``action_space(params)``
    where supported: an action the env lacks would be taken silently."""
    declared = task.action_space
    if declared is None:
        _task_size("task.num_actions", task.num_actions)
    elif not isinstance(declared, (acts.Discrete, acts.MultiDiscrete, acts.Box)):  # not even from_env_space reads it
        acts.from_env_space(declared, "task.action_space")  # raises: one line naming the spaces it reads
    elif declared.problem() is not None:
        raise ConfigError(f"task.action_space: {declared}: {declared.problem()}")
    else:  # the shorthand given beside it must say the same
        shorthand = declared.task_fields()
        clash = [f"{key}={value}" for key, value in (("num_actions", task.num_actions), ("continuous", task.continuous))
                 if value is not None and value is not False and shorthand.get(key) != value]
        if clash:
            raise ConfigError(f"task.num_actions: {', '.join(clash)} disagrees with action_space={declared}; give "
                              f"action_space alone")
    try:
        env_space = acts.from_env_space(task.env.action_space(task.params))
    except Exception:  # noqa: BLE001 (an environment without a usable, supported action space: nothing to compare)
        return
    mine = task.actions
    if env_space == mine:
        return
    if declared is None and type(env_space) is type(mine):  # the shorthand's count is off
        count = env_space.dims if isinstance(env_space, acts.Box) else env_space.n
        kind = "continuous action dimensions" if task.continuous else "actions"
        raise ConfigError(f"task.num_actions: must be the environment's {count} {kind} (its action_space), got "
                          f"{task.num_actions}")
    field = "action_space" if declared is not None else "num_actions"
    raise ConfigError(f"task.{field}: must be the environment's {env_space} (its action_space), got {mine}; declare "
                      f"action_space={env_space} (remidi.envs.actions)")


def _traced(field: str, what: str, fn, *args, hint: str = ""):
    """``jax.eval_shape(fn, *args)``; ConfigError ``task.FIELD: WHAT failed: ...`` when the user's code raises."""
    try:
        return jax.eval_shape(fn, *args)
    except Exception as err:  # noqa: BLE001 (the user's code: report its own error in one line)
        raise ConfigError(f"task.{field}: {what} failed: {_user_error(err)}{hint}") from None


def _is_scalar(x, kind: str) -> bool:
    """``x`` (a ShapeDtypeStruct) is a scalar of ``kind`` ("float" or "bool")."""
    if getattr(x, "shape", None) != ():
        return False
    dtype = jnp.dtype(x.dtype)
    return dtype == jnp.bool_ if kind == "bool" else jnp.issubdtype(dtype, jnp.floating)


def _task_size(field: str, value) -> None:
    """ConfigError unless ``value`` is an integer ≥ 1 (not a bool)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ConfigError(f"{field}: must be an integer ≥ 1, got {value!r}")


def _reset_reads_its_key(task: UEDTask, rng, level) -> bool:
    """Whether ``reset_to_level``'s outputs depend on its key (read from the traced program).

    Why: a false ``deterministic_reset`` would replay one start per level and mislead the trackers."""
    return _reads_key(lambda k, lv: task.env.reset_to_level(k, lv, task.params), rng, level)


def _reads_key(fn, key, *args, kept=lambda out: True) -> bool:
    """Whether the outputs of ``fn(key, *args)`` that ``kept`` marks depend on ``key``.

    Read by JAX's dead-code elimination of the traced program (nothing compiled). False where JAX
    lacks that internal pass or ``fn`` does not trace."""
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
    """ConfigError (one line naming the ``UEDTask`` field) for a task the engine cannot train.

    Checks field types and ranges and the action space, then traces abstractly (nothing compiled)
    one sampled level, its reset and a step: step and reset agree in shapes, reward is a float
    scalar and done a bool scalar; tags, optima, edited/easy/reseeded/built levels and evaluation
    sets have the right shapes and types. Once per task object."""
    if not isinstance(task, UEDTask):
        raise ConfigError(f"task: must be a remidi UEDTask, got {a_type(task)}")
    if task in _VALIDATED:
        return
    _task_size("task.max_episode_steps", task.max_episode_steps)
    for key in ("deterministic_reset", "continuous"):
        if not isinstance(getattr(task, key), bool):
            raise ConfigError(f"task.{key}: must be true or false, got {getattr(task, key)!r}")
    if not isinstance(task.env, UnderspecifiedEnv):
        raise ConfigError(f"task.env: must be a jaxued UnderspecifiedEnv, got {a_type(task.env)}")
    for key in ("sample_level", "level_tags"):
        if not callable(getattr(task, key)):
            raise ConfigError(f"task.{key}: must be a function, got {getattr(task, key)!r}")
    if task.solved is not None and not callable(task.solved) and not (isinstance(task.solved, str) and task.solved):
        raise ConfigError(f"task.solved: must be a function of the episode's return, the name of a key of the step's "
                          f"info, or None, got {task.solved!r}")
    for key in ("optimal_return", "optimal_discounted_return", "expected_return", "mutate_level",
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
            raise ConfigError(f"task.eval_envs: {name!r} must be a jaxued UnderspecifiedEnv, got {a_type(env)}")

    _check_actions(task)
    if task.expected_return is not None and not isinstance(task.actions, acts.Discrete):
        raise ConfigError(f"task.expected_return: reads a Discrete policy's action probabilities, but the actions are "
                          f"{task.actions}; allowed: None")

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
    action = acts.example_action(task.actions)
    stepped = _traced("env", "a step of the environment", lambda k, s, a: task.env.step(k, s, a, task.params),
                      rng, state, action, hint=f" (from a level of sample_level: {_shapes(level, 4)}) and an action "
                                               f"{_leaf(action)} of {task.actions}")
    if not isinstance(stepped, tuple) or len(stepped) != 5:
        raise ConfigError("task.env: step must return (obs, state, reward, done, info)")
    next_obs, next_state, reward, done, info = stepped
    if _difference(obs, next_obs) is not None:
        raise ConfigError(f"task.env: a step's observation must have the reset's shapes and dtypes; "
                          f"{_difference(obs, next_obs, 'at the reset')}")
    if _difference(state, next_state) is not None:
        raise ConfigError(f"task.env: a step's state must have the shapes and dtypes of the reset's state; "
                          f"{_difference(state, next_state, 'at the reset')}")
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
    if isinstance(task.solved, str):  # an info key: the step's info holds a flag (or flags) there
        if not isinstance(info, dict) or task.solved not in info:
            held = (f"only {', '.join(map(str, info))}" if info else "no key") if isinstance(info, dict) else \
                f"no dict but {a_type(info)}"
            raise ConfigError(f"task.solved: names the info key {task.solved!r}, but a step's info holds {held}")
        leaves = jax.tree.leaves(info[task.solved])
        if len(leaves) != 1 or not (jnp.issubdtype(leaves[0].dtype, jnp.bool_)
                                    or jnp.issubdtype(leaves[0].dtype, jnp.number)):
            raise ConfigError(f"task.solved: the step's info[{task.solved!r}] must be a boolean or a number (an array: "
                              f"solved when every entry is), got {_shapes(info[task.solved])}")
    elif task.solved is not None:
        value = _traced("solved", "judging returns", task.solved, jax.ShapeDtypeStruct((3,), jnp.float32))
        if getattr(value, "shape", None) != (3,) or jnp.dtype(value.dtype) != jnp.bool_:
            raise ConfigError(f"task.solved: must map returns f32[N] to booleans bool[N], got {_shapes(value)} for N = 3")
    for key, fn in (("mutate_level", lambda k, lv: task.mutate_level(k, lv, 1)),
                    ("easy_level", lambda k, lv: task.easy_level(k)),
                    ("reseed_level", lambda k, lv: task.reseed_level(k, lv))):
        if getattr(task, key) is not None:
            made = _traced(key, "making a level", fn, rng, level)
            if _difference(level, made) is not None:
                raise ConfigError(f"task.{key}: must return a level with the sampled level's shapes and dtypes; "
                                  f"{_difference(level, made, 'sampled')}")
    builder = task.level_builder
    if builder is not None:
        for key in ("num_steps", "num_actions"):
            _task_size(f"task.level_builder.{key}", getattr(builder, key, None))
        made = _traced("level_builder", "building a level from a whole design",
                       lambda k: builder.build(k, jnp.zeros((builder.num_steps,), jnp.int32)), rng)
        if _difference(level, made) is not None:
            raise ConfigError(f"task.level_builder: must build a level with the sampled level's shapes and dtypes; "
                              f"{_difference(level, made, 'sampled')}")

    for name, levels in task.eval_sets.items():
        leaves = jax.tree.leaves(levels)
        problem = _batch_problem(level, levels)
        if problem is not None:
            raise ConfigError(f"task.eval_sets: {name!r} must be a batch of levels, every leaf with the level's "
                              f"shape after one leading axis of the same length ≥ 1; {problem}")
        if any(not hasattr(leaf, "dtype") or jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key)
               for leaf in leaves):
            raise ConfigError(f"task.eval_sets: {name!r} must hold arrays (typed PRNG keys as jax.random.key_data), "
                              f"got {_shapes(levels, 4)}")
        one = jax.tree.map(lambda x: np.asarray(x)[0], levels)
        if name not in task.eval_envs and _difference(level, one) is not None:
            raise ConfigError(f"task.eval_sets: the levels of {name!r} must have the sampled level's dtypes and "
                              f"shapes; they differ in {_difference(level, one, 'sampled')} (NumPy's int64 or "
                              f"float64: cast them, e.g. with jnp.asarray)")
        env = task.eval_envs.get(name, task.env)
        first = _traced("eval_sets", f"resetting to a level of {name!r}",
                        lambda k, lvs, env=env: env.reset_to_level(k, jax.tree.map(lambda x: x[0], lvs),
                                                                   task.params)[0],
                        rng, levels)
        if _difference(obs, first) is not None:
            raise ConfigError(f"task.eval_sets: {name!r}'s levels give other observations than the training levels' "
                              f"(which the network reads): {_difference(obs, first, 'in training')}")
    _VALIDATED.add(task)


def _observation_batch(task: UEDTask, flat: bool):
    """The task's first observation as a ``[1, 1, ...]`` batch (flattened if ``flat``), shapes only.

    ConfigError with the env's own error if sampling or resetting fails."""
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


def _read_error(net, obs) -> str | None:
    """None if ``net`` reads the batch ``obs`` (leaves ``[1, 1, ...]``), else why (its
    ``check_observation``, then an abstract init)."""
    problem = observation_problem(net, jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[2:], x.dtype), obs))
    if problem is not None:
        return problem
    try:
        jax.eval_shape(lambda o: net.init(jax.random.PRNGKey(0), net.initialize_carry(1), o, jnp.ones((1, 1), bool)),
                       obs)
        return None
    except Exception as err:  # any failure to read the observation is the choice of network
        return f"the network failed on it: {_user_error(err)}"


def _fits(name: str, task: UEDTask, obs) -> bool:
    """Whether network ``name`` at its defaults reads ``obs``."""
    try:
        return _read_error(make_network(name, for_task(task).network_actions, for_task(task).continuous), obs) is None
    except Exception:  # noqa: BLE001 (a registered network that cannot even be built fits nothing)
        return False


def check_network_reads_observations(net, name: str, task: UEDTask, flat: bool = False) -> None:
    """ConfigError unless ``net`` reads the task's observations (flattened if ``flat``, as
    ``normalize_obs`` does); the message names the networks that can."""
    obs = _observation_batch(task, flat)
    problem = _read_error(net, obs)
    if problem is None:
        return
    fits = [other for other in NETWORKS if other != name and _fits(other, task, obs)]
    one = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape[2:], x.dtype), obs)
    what = "this task's observation" + (" (flattened by normalize_obs)" if flat else "")
    raise ConfigError(f"network: {name} reads {reads(net)}; {what} is {describe_observation(one)} ({problem}); "
                      f"allowed: {', '.join(fits) or 'none of ' + ', '.join(NETWORKS)}")


def step_reads_its_key(task: UEDTask) -> bool:
    """Whether ``step_env``'s observation, state or done depend on its key (traced once per task).

    A random reward or info alone does not count: the tracker does not compare them. False where JAX
    lacks the pass."""
    if task not in _STEP_READS_KEY:
        _STEP_READS_KEY[task] = _trace_step_key_use(task)
    return _STEP_READS_KEY[task]


def _trace_step_key_use(task: UEDTask) -> bool:
    try:  # shapes only: sampling and resetting eagerly would compile the generator and the reset (Kinetix: minutes)
        state = jax.eval_shape(lambda k: task.env.reset_to_level(k, task.sample_level(k), task.params)[1],
                               jax.random.PRNGKey(0))
    except Exception:  # noqa: BLE001 (validate_task reports a failing reset)
        return False
    action = acts.zero_action(task.actions)

    def kept(out):  # the tracker reads observations and ends (and the state carries them on), not reward or info
        obs, nstate, reward, done, info = out
        return jax.tree.map(lambda _: True, (obs, nstate)), jax.tree.map(lambda _: False, reward), \
            jax.tree.map(lambda _: True, done), jax.tree.map(lambda _: False, info)

    return _reads_key(lambda k, st: task.env.step_env(k, st, action, task.params), jax.random.PRNGKey(1), state,
                      kept=kept)
