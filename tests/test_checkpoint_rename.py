"""A checkpoint of the runner's earlier layout (one field per feature: ``.train_state``,
``.buffers``, ``.active``, ``.belief``, ...) loads through the one rename
(``engine/run/checkpoint.py`` RENAMES) into the layout of one state per component."""

import json
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from remidi.engine import train as tr
from remidi.engine.run.checkpoint import PREFIX, RENAMES, current_name, load_checkpoint


def test_the_earlier_layout_loads_through_the_rename(tmp_path):
    from test_ued_engine import TASK, TINY

    setup = tr.make_setup(TASK, TINY, "accel")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    runner = runner.replace(updates_done=jnp.asarray(7, jnp.int32))
    old_of = {new: old for old, new in RENAMES.items()}
    arrays = {}
    for path, leaf in jax.tree_util.tree_leaves_with_path(runner):
        name = jax.tree_util.keystr(path)
        head = next((new for new in sorted(old_of, key=len, reverse=True) if name.startswith(new + ".")
                     or name.startswith(new + "[") or name == new), None)
        old = old_of[head] + name[len(head):] if head else name
        assert current_name(old) == name
        arrays[PREFIX + old] = np.asarray(leaf)
    assert any(k.startswith(PREFIX + ".train_state") for k in arrays)
    assert any(k.startswith(PREFIX + ".edit_next") for k in arrays)
    path = tmp_path / "checkpoint.npz"
    np.savez(path, meta=np.asarray(json.dumps({"done": 7})), **arrays)
    loaded, meta = load_checkpoint(path, runner)
    assert meta == {"done": 7}
    for a, b in zip(jax.tree.leaves(runner), jax.tree.leaves(loaded)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


def test_dr_keeps_no_level_so_its_checkpoint_stores_none(tmp_path):
    """DR never fills a level buffer: its adversary's state holds one without a slot (the fields of
    every adversary's, nothing allocated), so its checkpoint stores no level; it used to store
    ``buffer.capacity`` empty ones (a maze run's 4000: most of an 89 MB checkpoint). The training
    is as before (tests/test_engine_reference.py's dr case, unchanged)."""
    import dataclasses

    from test_ued_engine import TASK, TINY

    from remidi.engine.run.driver import train_seeds

    cfg = dataclasses.replace(TINY, num_updates=10, buffer=dataclasses.replace(TINY.buffer, capacity=4000))
    result = train_seeds(TASK, cfg, "dr", [0, 1], out=tmp_path, progress=False)
    assert result.runner.adversary.buffers.valid.shape == (2, 1, 0)
    with np.load(tmp_path / "checkpoint.npz") as saved:
        buffers = {k: saved[k] for k in saved.files if k.startswith(PREFIX + ".adversary.buffers")}
    assert buffers and all(v.size == 0 for k, v in buffers.items() if not k.endswith(".time")), \
        {k: v.shape for k, v in buffers.items()}
    plr = tr.init_runner(tr.make_setup(TASK, cfg, "plr"), jax.random.PRNGKey(0))
    assert plr.adversary.buffers.valid.shape == (1, 4000)  # an adversary that keeps levels keeps its buffer


def test_a_dr_checkpoint_of_the_full_unused_buffer_still_resumes(tmp_path):
    """A DR checkpoint written while DR's state held an unfilled buffer of ``buffer.capacity``
    levels loads into today's state (the buffer read as the empty one); a buffer holding
    anything is no such checkpoint and is refused."""
    from test_ued_engine import TASK, TINY

    from remidi.engine.adversaries.base import empty_buffers
    from remidi.engine.run.checkpoint import save_checkpoint
    from remidi.engine.setup import example_observation
    from remidi.errors import ConfigError

    setup = tr.make_setup(TASK, TINY, "dr")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0)).replace(updates_done=jnp.asarray(7, jnp.int32))
    full = empty_buffers(setup, example_observation(TASK)[1])  # what DR's state held before: [1, 16, ...]
    assert full.valid.shape == (1, 16) and runner.adversary.buffers.valid.shape == (1, 0)
    old = runner.replace(adversary=runner.adversary.replace(buffers=full))
    path = tmp_path / "checkpoint.npz"
    save_checkpoint(path, old, {"done": 7})
    loaded, meta = load_checkpoint(path, runner)
    assert meta == {"done": 7} and int(loaded.updates_done) == 7
    assert jax.tree.structure(loaded) == jax.tree.structure(runner)
    for a, b in zip(jax.tree.leaves(runner), jax.tree.leaves(loaded)):
        assert a.shape == b.shape and a.dtype == b.dtype
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    filled = old.replace(adversary=old.adversary.replace(buffers=full.replace(scores=full.scores + 1.0)))
    save_checkpoint(path, filled, {"done": 7})
    with pytest.raises(ConfigError, match=re.escape("does not match the run's config.json (.adversary.buffers.scores "
                                                    "is float32[1, 16]")):
        load_checkpoint(path, runner)
