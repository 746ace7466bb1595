"""Regression: initialising many seeds must not hang.

With jaxlib 0.10.2 on CPU, several *batched* QR decompositions in one program (orthogonal
initialisers under ``vmap`` over seeds) sometimes never finish; the driver initialises seeds one
after another with ``lax.map``. The check runs in a subprocess so a hang fails the test instead
of stalling the suite.
"""

import subprocess
import sys

from conftest import subprocess_env

SCRIPT = """
import jax, jax.numpy as jnp
from remidi.engine import driver, train as tr
from remidi.envs.lever import lever_task
from remidi.experiments.lever import paper_config
setup = tr.make_setup(lever_task(64), paper_config(), "dr")
runner = driver._init(setup, jax.vmap(jax.random.PRNGKey)(jnp.arange(8, dtype=jnp.uint32)))
jax.block_until_ready(runner)
print("initialised", runner.train_state.step.shape)
"""


def test_initialising_eight_seeds_finishes():
    done = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120,
                          env=subprocess_env(__name__))
    assert done.returncode == 0, done.stderr[-2000:]
    assert "initialised (8,)" in done.stdout
