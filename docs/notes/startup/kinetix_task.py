"""A Kinetix task for ``remidi run kinetix_task:make_task``, written from outside as a user would
(docs/notes/kinetix-api.md): size-s levels from Kinetix's own (unfiltered) sampler, flat symbolic
observations (f32[140]) and the 11 discrete actions, an adapter to jaxued's interface; no optimum
(perfect regret is unavailable), ``solved`` from the return. Used to measure start-up
(docs/performance.md, "Start-up"); run it under the Kinetix venv:

    PYTHONPATH=$PWD/src:$PWD/docs/notes/startup /tmp/kinetix-venv/bin/python -m remidi run \
        kinetix_task:make_task --algo remidi --seeds 1 --set num_updates=4 ...
"""

import jax
import jax.numpy as jnp
from kinetix.environment import (ActionType, EnvParams, ObservationType, UEDParams, make_kinetix_env,
                                 static_env_params_from_size)
from kinetix.environment.ued.ued import make_reset_fn_sample_kinetix_level

from remidi.envs.interface import UEDTask, UnderspecifiedEnv

STATIC = static_env_params_from_size("s")
PARAMS = EnvParams()
UED_PARAMS = UEDParams()  # one instance: it compares by identity and is a static jit argument


class KinetixUnderspecified(UnderspecifiedEnv):
    """Kinetix without its own auto-reset (remidi's AutoReplay restarts the level)."""

    def __init__(self):
        self._env = make_kinetix_env(ActionType.DISCRETE, ObservationType.SYMBOLIC_FLAT, None, PARAMS, STATIC,
                                     auto_reset=False)

    @property
    def default_params(self):
        return PARAMS

    def action_space(self, params):
        return self._env.action_space(params)

    def reset_env_to_level(self, rng, level, params):
        return self._env.reset(rng, params, level)

    def step_env(self, rng, state, action, params):
        obs, state, reward, done, info = self._env.step(rng, state, action, params)
        return obs, state, jnp.asarray(reward, jnp.float32), jnp.asarray(done, bool), {}

    def __hash__(self):
        return hash(self._env)

    def __eq__(self, other):
        return isinstance(other, KinetixUnderspecified) and self._env == other._env


_TASK = []


def make_task() -> UEDTask:
    if _TASK:
        return _TASK[0]
    env = KinetixUnderspecified()
    sample = make_reset_fn_sample_kinetix_level(PARAMS, STATIC, UED_PARAMS, physics_engine=env._env.physics_engine)
    held_out = jax.vmap(sample)(jax.random.split(jax.random.PRNGKey(100), 4))  # 4 sampled levels, fixed
    _TASK.append(UEDTask(env=env, params=PARAMS, sample_level=sample, num_actions=11, max_episode_steps=256,
                         eval_sets={"sampled": held_out}, solved=lambda ret: ret > 0.9,  # +1 at the goal, shaping aside
                         deterministic_reset=True))
    return _TASK[0]
