"""A checkpoint of the runner's earlier layout (one field per feature: ``.train_state``,
``.buffers``, ``.active``, ``.belief``, ...) loads through the one rename
(``engine/run/checkpoint.py`` RENAMES) into the layout of one state per component."""

import json

import jax
import jax.numpy as jnp
import numpy as np

from remidi.engine import train as tr
from remidi.engine.run.checkpoint import PREFIX, RENAMES, current_name, load_checkpoint


def test_the_earlier_layout_loads_through_the_rename(tmp_path):
    from test_ued_engine import TASK, TINY

    setup = tr.make_setup(TASK, TINY, "accel")
    runner = tr.init_runner(setup, jax.random.PRNGKey(0))
    runner = runner.replace(update=jnp.asarray(7, jnp.int32))
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
