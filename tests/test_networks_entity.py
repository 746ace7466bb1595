"""The entity and pixel networks (remidi.engine.core.networks.entity, .cnn) and registering a
network: permutation invariance, masked entities ignored, all-masked groups without NaN, finite
gradients, the CNN's shapes, and every refusal in one line. Tiny sizes, run eagerly (nothing
compiled): seconds."""

import dataclasses
from types import SimpleNamespace

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import remidi
from remidi.engine.core.networks import NETWORKS, make_network
from remidi.engine.core.networks import entity
from remidi.engine.run import task_checks
from remidi.errors import ConfigError

T, N, A = 2, 3, 4
SMALL = {"embed": 16, "num_heads": 2, "qkv_features": 8, "head_hidden": 8}


def entity_obs(key, sizes=(("circles", 4, 3), ("polygons", 3, 5)), globals_=2):
    """An entity observation batch ``[T, N, ...]``: each group ``(name, n, F)`` with random
    features and a random mask (env 0's first group all masked), and ``globals`` of width
    ``globals_``."""
    keys = jax.random.split(key, 2 * len(sizes) + 1)
    groups = {}
    for i, (name, n, width) in enumerate(sizes):
        mask = jax.random.bernoulli(keys[2 * i], 0.6, (T, N, n))
        groups[name] = {"features": jax.random.normal(keys[2 * i + 1], (T, N, n, width)),
                        "mask": mask.at[:, 0].set(False) if i == 0 else mask}
    return {"entities": groups, "globals": jax.random.normal(keys[-1], (T, N, globals_))}


RESET = jnp.zeros((T, N), bool).at[1, 1].set(True)

ENCODERS = [{"encoder": "attention", "pool": "mean", "lstm_size": 4}, {"encoder": "pool", "pool": "max"}]


@pytest.fixture(scope="module", params=ENCODERS, ids=lambda o: "-".join(str(v) for v in o.values()))
def entity_net(request):
    """``(net, params, obs, apply, grad)``: ``apply(params, obs) -> (logits, value, carry)`` and
    ``grad(params, obs)``, the gradient of the outputs' sum of squares, each compiled once."""
    net = make_network("entity", A, **SMALL, **request.param)
    obs = entity_obs(jax.random.PRNGKey(0))
    params = jax.jit(net.init)(jax.random.PRNGKey(1), net.initialize_carry(N), obs, RESET)

    def apply(p, o):
        carry, (logits, value) = net.apply(p, net.initialize_carry(N), o, RESET)
        return logits, value, carry

    def loss(p, o):
        logits, value, _ = apply(p, o)
        return jnp.sum(logits ** 2) + jnp.sum(value ** 2)

    return net, params, obs, jax.jit(apply), jax.jit(jax.grad(loss))


def test_entity_outputs_have_the_interfaces_shapes(entity_net):
    net, params, obs, apply, grad = entity_net
    logits, value, carry = apply(params, obs)
    assert logits.shape == (T, N, A) and value.shape == (T, N)
    assert jax.tree.structure(carry) == jax.tree.structure(net.initialize_carry(N))
    assert all(np.isfinite(x).all() for x in (logits, value))


def _shuffled(obs):
    """``obs`` with the rows of every entity group in another order (features and mask alike)."""
    shuffled = jax.tree.map(lambda x: x, obs)
    for i, (name, group) in enumerate(sorted(obs["entities"].items())):
        order = jax.random.permutation(jax.random.PRNGKey(10 + i), group["mask"].shape[-1])
        shuffled["entities"][name] = {"features": group["features"][:, :, order], "mask": group["mask"][:, :, order]}
    assert all(not np.array_equal(shuffled["entities"][name]["mask"], obs["entities"][name]["mask"])
               for name in obs["entities"])  # valid and padded rows trade places in every group
    return shuffled


def test_shuffling_entities_within_a_group_leaves_the_outputs_unchanged(entity_net):
    net, params, obs, apply, grad = entity_net
    shuffled = _shuffled(obs)
    for a, b in zip(apply(params, obs)[:2], apply(params, shuffled)[:2]):
        np.testing.assert_allclose(a, b, atol=1e-5, rtol=1e-5)


def test_the_shuffle_changes_what_a_network_reading_row_positions_outputs():
    """The control of the test above: a dense layer over the groups' rows laid side by side (a
    network that reads where each entity sits) answers the shuffled observation differently."""
    class Positional(nn.Module):
        @nn.compact
        def __call__(self, obs):
            rows = [jnp.where(g["mask"][..., None], g["features"], 0.0).reshape(T, N, -1)
                    for _, g in sorted(obs["entities"].items())]
            return nn.Dense(A)(jnp.concatenate(rows, axis=-1))

    obs = entity_obs(jax.random.PRNGKey(0))
    net = Positional()
    params = net.init(jax.random.PRNGKey(1), obs)
    assert not np.allclose(net.apply(params, obs), net.apply(params, _shuffled(obs)), atol=1e-3)


def test_a_masked_entitys_features_do_not_reach_the_output(entity_net):
    net, params, obs, apply, grad = entity_net
    garbage = jax.tree.map(lambda x: x, obs)
    for value, (name, group) in zip((jnp.nan, 1e6), sorted(obs["entities"].items())):  # NaN in one, 1e6 in the other
        garbage["entities"][name] = {"features": jnp.where(group["mask"][..., None], group["features"], value),
                                     "mask": group["mask"]}
    for a, b in zip(apply(params, obs)[:2], apply(params, garbage)[:2]):
        np.testing.assert_array_equal(a, b)
    # and a valid entity's do
    changed = jax.tree.map(lambda x: x, obs)
    group = obs["entities"]["polygons"]
    changed["entities"]["polygons"] = {"features": group["features"] + 1.0, "mask": group["mask"]}
    assert not np.allclose(apply(params, obs)[1], apply(params, changed)[1])


def test_all_masked_groups_and_observations_give_finite_outputs_and_gradients(entity_net):
    """Env 0's first group is all masked in the fixture; here every entity of every env is too."""
    net, params, obs, apply, grad = entity_net
    empty = jax.tree.map(lambda x: x, obs)
    for name, group in obs["entities"].items():
        empty["entities"][name] = {"features": group["features"], "mask": jnp.zeros_like(group["mask"])}
    for batch in (obs, empty):
        grads = grad(params, batch)
        assert all(np.isfinite(g).all() for g in jax.tree.leaves(grads))
        assert any(np.abs(g).sum() > 0 for g in jax.tree.leaves(grads))
        assert all(np.isfinite(x).all() for x in apply(params, batch)[:2])


def test_groups_of_different_widths_each_have_their_own_embedding():
    net = make_network("entity", A, **SMALL, encoder="pool")
    obs = entity_obs(jax.random.PRNGKey(0), sizes=(("a", 2, 1), ("b", 5, 7), ("c", 1, 2)), globals_=3)
    shapes = jax.eval_shape(lambda: net.init(jax.random.PRNGKey(0), net.initialize_carry(N), obs, RESET))["params"]
    assert [shapes[f"group{g}_0"]["kernel"].shape for g in range(3)] == [(1, 13), (7, 13), (2, 13)]  # 16 − 3 types
    assert shapes["globals"]["kernel"].shape == (3, 16) and "lstm" not in shapes


@pytest.mark.parametrize("image_obs", ["array", "dict"])
def test_cnn_output_shapes(image_obs):
    """Shapes traced abstractly (nothing compiled)."""
    image = jax.ShapeDtypeStruct((T, N, 20, 17, 3), jnp.uint8)
    info = jax.ShapeDtypeStruct((T, N, 1), jnp.float32)
    obs = image if image_obs == "array" else {"image": image, "global_info": info}
    for lstm_size, continuous in ((0, False), (5, False), (0, True)):
        net = make_network("cnn", A, continuous, lstm_size=lstm_size, head_hidden=8)

        def run(o, net=net):
            params = net.init(jax.random.PRNGKey(1), net.initialize_carry(N), o, RESET)
            return params, net.apply(params, net.initialize_carry(N), o, RESET)

        params, (carry, (logits, value)) = jax.eval_shape(run, obs)
        assert logits.shape == (T, N, 2 * A if continuous else A) and value.shape == (T, N)
        # SAME padding: 20×17 → 5×5 (stride 4) → 3×3 (stride 2), 32 channels, plus global_info
        features = params["params"]["heads"]["policy_hidden"]["kernel"].shape[0]
        assert features == (lstm_size or 9 * 32 + (image_obs == "dict"))
        assert (carry[0].shape == (N, 5)) if lstm_size else carry.shape == (N,)


def refusal(monkeypatch, network, obs, **options):
    """The one-line ConfigError of validating ``network`` on a task whose observation is ``obs``
    (one observation; the task's reset is replaced by it)."""
    batch = jax.tree.map(lambda x: jax.ShapeDtypeStruct((1, 1) + x.shape, x.dtype), obs)
    monkeypatch.setattr(task_checks, "_observation_batch", lambda task, flat: batch)
    task = SimpleNamespace(num_actions=3, continuous=False)
    with pytest.raises(ConfigError) as err:
        task_checks.check_network_reads_observations(make_network(network, 3, **options), network, task)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"network: {network} reads ")
    return message


def allowed_networks(message: str) -> list[str]:
    """The networks a refusal offers instead (after its last "; allowed: "): registered ones, in
    the registry's order."""
    allowed = message.rsplit("; allowed: ", 1)[1].split(", ")
    assert allowed == [name for name in NETWORKS if name in allowed], allowed
    return allowed


def test_each_refusal_is_one_line_naming_what_the_network_reads(monkeypatch):
    flat = jnp.zeros(65)
    group = {"features": jnp.zeros((3, 4)), "mask": jnp.ones(3, bool)}
    message = refusal(monkeypatch, "entity", flat)
    assert "this task's observation is f32[65] (not a dict with a key entities); allowed: " in message
    # a flat vector: the networks with a fully-connected trunk read it, none that needs fields
    assert {"mlp", "mlp_lstm"} <= set(allowed_networks(message))
    assert not {"entity", "cnn", "maze_lstm"} & set(allowed_networks(message))
    message = refusal(monkeypatch, "entity", {"entities": {"a": {"features": group["features"], "mask": jnp.ones(3)}}})
    assert "entities.a.mask f32[3]" in message and "(its group a's mask is f32[3], not bool[3])" in message
    assert "(it has keys other than entities and globals: global)" in refusal(
        monkeypatch, "entity", {"entities": {"a": group}, "global": jnp.zeros(2)})
    assert "(its group a is not a dict with features and mask)" in refusal(
        monkeypatch, "entity", {"entities": {"a": {"features": jnp.zeros((3, 4))}}})
    message = refusal(monkeypatch, "cnn", flat)
    assert "is f32[65] (its image is f32[65], not [H, W, C]); allowed: " in message
    assert {"mlp", "mlp_lstm"} <= set(allowed_networks(message)) and "cnn" not in allowed_networks(message)
    message = refusal(monkeypatch, "maze_lstm", {"entities": {"a": group}})
    assert "(not a dict or object with a field image); allowed: " in message
    assert {"mlp", "mlp_lstm", "entity"} <= set(allowed_networks(message))  # MLPs read the flattened entities
    assert not {"cnn", "maze_lstm"} & set(allowed_networks(message))
    assert "(its image is f32[2, 2, 3], not [H, W, C] with H, W ≥ 3)" in refusal(
        monkeypatch, "maze_lstm", {"image": jnp.zeros((2, 2, 3)), "agent_dir": jnp.zeros((), jnp.int32)})


@pytest.mark.parametrize("options, needle", [
    ({"encoder": "gnn"}, f"network.encoder: unknown value 'gnn'; allowed: {', '.join(entity.ENCODERS)}"),
    ({"pool": "sum"}, f"network.pool: unknown value 'sum'; allowed: {', '.join(entity.POOLS)}"),
    ({"qkv_features": 6}, "network.qkv_features: must be a multiple of num_heads (8), got 6"),
])
def test_bad_entity_options_are_one_line(options, needle):
    with pytest.raises(ConfigError, match="^" + needle.replace("(", r"\(").replace(")", r"\)") + "$"):
        make_network("entity", 3, **options)


class Linear(nn.Module):
    """A linear actor-critic over the flattened observation: the smallest registered network."""

    reads = "one vector f32[D]"
    num_actions: int
    continuous: bool = False

    @nn.nowrap
    def initialize_carry(self, n):
        return jnp.zeros((n,), jnp.float32)

    @nn.nowrap
    def check_observation(self, obs):
        return None if hasattr(obs, "shape") and len(obs.shape) == 1 else "not one vector"

    @nn.compact
    def __call__(self, carry, obs, reset):
        return carry, (nn.Dense(self.num_actions)(obs), nn.Dense(1)(obs)[..., 0])


def test_a_registered_network_is_built_listed_and_checked(monkeypatch, capsys, restore_registries):
    from remidi.cli import main
    from remidi.engine.config import UEDConfig
    from remidi.engine.setup import network_for

    assert remidi.register_network("linear", Linear, description="a linear policy") is Linear
    net = network_for(UEDConfig(network="linear"), SimpleNamespace(num_actions=5, continuous=False))
    assert isinstance(net, Linear) and net.num_actions == 5
    with pytest.raises(ConfigError, match="^lstm_size: the network linear has no such layer"):
        network_for(UEDConfig(network="linear", lstm_size=8), SimpleNamespace(num_actions=5, continuous=False))
    assert "(not one vector)" in refusal(monkeypatch, "linear", {"image": jnp.zeros((5, 5, 3))})
    assert main(["list", "lever"]) == 0
    assert "    linear     reads one vector f32[D]; a linear policy" in capsys.readouterr().out.splitlines()


class NoReads(Linear):
    reads = None


class NoDefault(nn.Module):
    reads = "x"
    num_actions: int
    width: int
    continuous: bool = False
    initialize_carry = Linear.initialize_carry


class NoCarry(nn.Module):
    reads = "x"
    num_actions: int
    continuous: bool = False


@pytest.mark.parametrize("call, needle", [
    (lambda: remidi.register_network("mlp", Linear), "a network named 'mlp' is already registered; taken: mlp, "),
    (lambda: remidi.register_network("my net", Linear), "name must be a non-empty string"),
    (lambda: remidi.register_network("x", Linear(3)), "x: cls must be the class, not an instance (Linear)"),
    (lambda: remidi.register_network("x", dict), "x: cls must be a flax.linen.Module class, got <class 'dict'>"),
    (lambda: remidi.register_network("x", NoReads), "x: NoReads must state what it reads: a class attribute reads"),
    (lambda: remidi.register_network("x", NoDefault), "every field but num_actions and continuous needs a default"),
    (lambda: remidi.register_network("x", NoCarry), "x: NoCarry must have an nn.nowrap method initialize_carry(n)"),
    (lambda: remidi.register_network("x", Linear, description="two\nlines"), "x: description must be one line"),
])
def test_a_malformed_registration_is_one_line_and_registers_nothing(call, needle, restore_registries):
    before = dict(NETWORKS)
    with pytest.raises(ConfigError) as err:
        call()
    assert str(err.value).startswith("register_network: ") and needle in str(err.value), str(err.value)
    assert "\n" not in str(err.value) and NETWORKS == before


class EntityLever:
    """The lever game (8 levers) observed as entities: a group ``levers`` of 8 real rows
    ``[index / 8, is the correct one and visible]`` and 4 padded ones, a group ``sign`` of one
    entity ``[visible]``, and ``globals`` ``[visible]``."""

    @staticmethod
    def make_task():
        from remidi.envs.lever import LeverGame, lever_task

        class Game(LeverGame):
            def observation(self, level):
                index = jnp.arange(12, dtype=jnp.float32)
                correct = (index == level.correct) & level.visible
                levers = {"features": jnp.stack([index / 8, correct.astype(jnp.float32)], axis=-1),
                          "mask": index < 8}
                visible = level.visible.astype(jnp.float32)[None]
                return {"entities": {"levers": levers, "sign": {"features": visible[None], "mask": jnp.ones(1, bool)}},
                        "globals": visible}

        return dataclasses.replace(lever_task(8), env=Game(8))


@pytest.mark.slow
def test_the_entity_network_trains_remidi_through_the_engine():
    """A few ReMiDi updates with network=entity (attention, and an LSTM) on entity observations:
    validated, rolled out, tracked (the frozen buffer's levels compared entity by entity),
    trained, evaluated; the evaluation finite and the network's parameters those of the entity encoder."""
    from test_ued_engine import TINY

    from remidi.engine.run import driver

    cfg = dataclasses.replace(TINY, network="entity", hidden_size=0, lstm_size=8, num_updates=12, eval_every=6,
                              checkpoint_every=6)
    result = driver.train_seeds(EntityLever.make_task(), cfg, "remidi", [0], progress=False)
    final = {k: np.asarray(v)[-1] for k, v in result.history.items()}
    assert np.isfinite(final["solve_rate/visible"]).all() and np.isfinite(final["return/hidden"]).all()
    params = result.runner.learner.train_state.params
    assert {"attention_0", "attention_1", "lstm", "heads", "group0_0", "group1_0", "globals"} <= set(params)
