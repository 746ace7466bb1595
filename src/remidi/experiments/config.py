"""Experiment configuration: presets, ``--set key=value`` overrides and validation.

An experiment's configuration is a frozen dataclass whose defaults are the paper's values. A
preset is a dict of overrides (``paper`` is empty), and ``--set`` adds more on top. Keys may be
dotted to reach nested dataclasses (``--set ppo.lr=3e-4``). Every problem raises
:class:`~remidi.errors.ConfigError` with one line naming the key and what is allowed.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import typing
from typing import Any, Iterable

from remidi.errors import ConfigError
# the validation helpers live in remidi.errors (the engine uses them too); the experiments import them from here
from remidi.errors import choice, non_negative, positive, positive_int, probability, require  # noqa: F401


def parse_set_items(items: Iterable[str]) -> dict[str, str]:
    """``["a=1", "b.c=x"]`` → ``{"a": "1", "b.c": "x"}``."""
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise ConfigError(f"--set: expected key=value, got {item!r}")
        out[key] = value.strip()
    return out


def field_names(config) -> list[str]:
    """All settable keys of a (nested) config dataclass, dotted, in declaration order.

    A config class (or any of its base classes) may name keys it derives itself in a
    ``DERIVED_KEYS`` attribute of the module that defines it
    (e.g. ``ppo.total_updates`` follows ``num_updates``); those are not settable.
    """
    derived = {key for cls in type(config).__mro__
               for key in getattr(sys.modules.get(cls.__module__), "DERIVED_KEYS", ())}
    names = []
    for f in dataclasses.fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            names += [f"{f.name}.{sub}" for sub in field_names(value) if f"{f.name}.{sub}" not in derived]
        elif f.name not in derived:
            names.append(f.name)
    return names


# One line per settable key, shown by `remidi list`. A config dataclass may instead carry its own
# text as ``dataclasses.field(metadata={"help": ...})``, which takes precedence.
HELP = {
    # tabular UED (tabular-distinct, tabular-shared)
    "iterations": "training iterations (each: adversary updates, then agent updates)",
    "adversary_updates": "adversary (level distribution) gradient steps per iteration",
    "agent_updates": "agent (policy) gradient steps per iteration",
    "policy_lr": "learning rate of both players' logits",
    "value_lr": "learning rate of the critics (SGD), in (0, 1]",
    "agent_entropy": "agent's entropy bonus (coefficient × entropy averaged over observations)",
    "adversary_entropy": "adversary's entropy bonus",
    "gamma": "discount (one-step episodes: has no effect)",
    "optimizer": "optimizer of the logits: adam or sgd",
    "adam_b1": "Adam's β1 (0: no momentum; 0.9 makes the players cycle)",
    "init_scale": "std of the initial logits (the only source of seed variation)",
    "num_adversaries": "remidi: number of (policy, adversary) pairs; mmr uses 1",
    "iters_per_adversary": "remidi: iterations before the next adversary takes over",
    "support_threshold": "remidi: a level is in an adversary's support at ≥ this × its largest probability",
    "log_every": "iterations between logged points",
    # the UED engine (lever, tmaze, blindfold)
    "num_updates": "train steps (one rollout + one PPO update or buffer insertion each)",
    "num_envs": "parallel environments (levels) per train step",
    "num_steps": "environment steps per env per rollout",
    "score": "level score of the PLR family: perfect_regret, pvl, maxmc, neg_return, learnability (SFL: p(1 − p), "
             "p the level's solve rate in the rollout)",
    "discounted_regret": "perfect_regret on the paper's discounted utility Σ γ^t r_t (γ = ppo.gamma), both "
                         "the optimum and the agent's return; false: undiscounted on both sides",
    "network": "actor-critic: mlp, maze_lstm or mlp_lstm",
    "hidden_size": "width of each fully-connected trunk layer (0: the network's default)",
    "lstm_size": "units of the network's LSTM (0: the network's default)",
    "reward_scale": "PPO learns from reward × reward_scale (returns and scores stay unscaled)",
    "normalize_obs": "normalise observations by their running mean and std (kept in checkpoints)",
    "eval_every": "updates between evaluations (and logged points)",
    "eval_attempts": "sampled attempts per evaluation level",
    "checkpoint_every": "updates between checkpoints (checkpoint.npz in the run folder)",
    "ppo.gamma": "discount factor",
    "ppo.gae_lambda": "GAE λ",
    "ppo.clip_eps": "PPO ratio clipping ε",
    "ppo.clip_value": "clip the value loss like the policy ratio",
    "ppo.vf_coef": "value-loss coefficient",
    "ppo.ent_coef": "entropy-bonus coefficient",
    "ppo.epochs": "PPO epochs per update",
    "ppo.minibatches": "minibatches per epoch (must divide num_envs)",
    "ppo.lr": "Adam learning rate",
    "ppo.anneal_lr": "decay the learning rate linearly to 0 over the run",
    "ppo.adam_eps": "Adam ε",
    "ppo.max_grad_norm": "global gradient-norm clipping",
    "buffer.capacity": "PLR level buffer size (plr, minimax-return)",
    "buffer.prioritization": "replay sampling: rank or topk",
    "buffer.temperature": "β of rank prioritisation",
    "buffer.topk_k": "k of top-k prioritisation",
    "buffer.staleness_coef": "ρ: weight of staleness in the replay distribution",
    "buffer.replay_prob": "probability that a train step replays buffer levels",
    "buffer.min_fill": "fraction of the buffer that must be filled before replay",
    "buffer.duplicate_check": "re-inserting a level already in the buffer updates it",
    "remidi.num_buffers": "ReMiDi: number of level buffers (adversaries) in sequence",
    "remidi.buffer_capacity": "ReMiDi: size of each buffer",
    "remidi.steps_per_buffer": "ReMiDi: updates (train steps) on a buffer before it is frozen (replays with remidi.count=replays)",
    "remidi.count": "ReMiDi: what steps_per_buffer counts: updates (every preset: the paper's and its authors' unit) or replays",
    "remidi.tracker": "ReMiDi: prefix (one frozen level made the whole prefix) or per_step (authors' rule)",
    "remidi.tracker_budget": "ReMiDi: frozen levels tracked per env (0: all, the reference tracker)",
    "remidi.policy": "ReMiDi: masked (one network) or combine (a frozen policy per buffer)",
    # the maze domain (tmaze, blindfold)
    "maze.prob": "probability that a generated level is a T-maze (tmaze) or blindfolded (blindfold)",
    "maze.num_walls": "walls of a random 13×13 maze",
}


def key_help(config, key: str) -> str:
    """The one-line description of the dotted ``key`` of ``config``: the field's ``help``
    metadata, else :data:`HELP`, else ``""``."""

    def from_metadata(cfg, dotted: str) -> str:
        head, _, rest = dotted.partition(".")
        for f in dataclasses.fields(cfg):
            if f.name == head:
                return from_metadata(getattr(cfg, head), rest) if rest else f.metadata.get("help", "")
        return ""

    return from_metadata(config, key) or HELP.get(key, "")


def _convert(key: str, text: Any, kind) -> Any:
    """Convert ``text`` (a string from the command line, or a JSON value) to ``kind``."""
    if kind is bool:
        if isinstance(text, bool):
            return text
        lowered = str(text).lower()
        if lowered in ("true", "1", "yes", "on"):
            return True
        if lowered in ("false", "0", "no", "off"):
            return False
        raise ConfigError(f"{key}: expected true or false, got {text!r}")
    if kind is int:
        if isinstance(text, bool):
            raise ConfigError(f"{key}: expected an integer, got {text!r}")
        try:
            number = float(text)
        except (TypeError, ValueError):
            raise ConfigError(f"{key}: expected an integer, got {text!r}") from None
        if not math.isfinite(number) or number != int(number):
            raise ConfigError(f"{key}: expected an integer, got {text!r}")
        return int(number)
    if kind is float:
        if isinstance(text, bool):
            raise ConfigError(f"{key}: expected a number, got {text!r}")
        try:
            number = float(text)
        except (TypeError, ValueError):
            raise ConfigError(f"{key}: expected a number, got {text!r}") from None
        if not math.isfinite(number):
            raise ConfigError(f"{key}: expected a finite number, got {text!r}")
        return number
    if kind is str:
        return str(text)
    raise ConfigError(f"{key}: cannot be set from the command line")


def apply_overrides(config, overrides: dict[str, Any], *, source: str = "--set", prefix: str = ""):
    """Return ``config`` with ``overrides`` (dotted keys → text or JSON values) applied.
    ``prefix``: the dotted path of ``config`` inside the top-level config, for error messages."""
    allowed = field_names(config)
    nested: dict[str, dict[str, Any]] = {}
    direct: dict[str, Any] = {}
    hints = typing.get_type_hints(type(config))
    for key, value in overrides.items():
        if key not in allowed:
            raise ConfigError(f"{source}: unknown key {prefix + key!r}; "
                              f"allowed: {', '.join(prefix + name for name in allowed)}")
        head, _, rest = key.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = _convert(prefix + key, value, hints[head])
    for head, sub in nested.items():
        direct[head] = apply_overrides(getattr(config, head), sub, source=source, prefix=f"{prefix}{head}.")
    return dataclasses.replace(config, **direct)


def get_value(config, key: str) -> Any:
    """The value of the dotted ``key`` in ``config`` (``get_value(cfg, "ppo.lr")``)."""
    for part in key.split("."):
        config = getattr(config, part)
    return config


def nearest_divisor(length: int, target: float) -> int:
    """The divisor of ``length`` closest to ``target`` in ratio (|log(d / target)|; the larger on
    a tie): 20 updates at a target of 3.3 give 4; a prime length gives itself or 1."""
    if length >= 2**31:  # no run is that long (validation refuses it): no divisor search over it
        return max(1, int(math.floor(target + 0.5)))
    small = [d for d in range(1, math.isqrt(length) + 1) if length % d == 0]
    divisors = small + [length // d for d in small]
    return min(divisors, key=lambda d: (abs(math.log(d / max(target, 1e-9))), -d))


def scale_dependents(config, base, overrides: dict[str, Any], rules: dict[str, tuple[str, ...]],
                     divisors: tuple[str, ...] = ()):
    """Scale the keys that depend on a length the user changed, in proportion.

    ``rules`` maps a length (``num_updates``) to the keys measured against it (``eval_every``,
    ``checkpoint_every``, ``remidi.steps_per_buffer``). When ``overrides`` set the length but not
    a dependent key, that key becomes ``max(1, round(base value × new length / base length))``,
    ``base`` being the preset's configuration, so that ``--set num_updates=20`` alone gives a
    run with the preset's proportions. Returns ``(config, note)``, ``note`` one line saying what
    was scaled (``None`` if nothing was). A key in ``divisors`` (a block length, e.g. ``eval_every``:
    a short last block would compile another program) becomes the divisor of the new length
    nearest to that value instead.
    """
    scaled: dict[str, int] = {}
    parts = []
    for length, dependents in rules.items():
        if length not in overrides:
            continue
        old, new = get_value(base, length), get_value(config, length)
        if not (isinstance(old, int) and isinstance(new, int)) or old < 1 or new < 1 or old == new:
            continue
        changes = []
        for key in dependents:
            if key in overrides:
                continue
            value = get_value(base, key)
            target = (nearest_divisor(new, value * new / old) if key in divisors
                      else max(1, int(math.floor(value * new / old + 0.5))))
            if target != value:
                scaled[key] = target
                changes.append(f"{key} {value} → {target}")
        if changes:
            parts.append(f"{length} {old} → {new}, so scaled {', '.join(changes)}")
    if not scaled:
        return config, None
    config = apply_overrides(config, scaled, source="scaling")
    return config, f"{'; '.join(parts)} (set them with --set to choose other values)"


def config_to_dict(config) -> dict[str, Any]:
    return dataclasses.asdict(config)


def config_from_dict(cls, data: dict[str, Any]):
    """Rebuild a config dataclass from :func:`config_to_dict` output (e.g. a run's config.json)."""
    flat: dict[str, Any] = {}

    def walk(prefix, d):
        for k, v in d.items():
            if isinstance(v, dict):
                walk(f"{prefix}{k}.", v)
            else:
                flat[f"{prefix}{k}"] = v

    walk("", data)
    settable = set(field_names(cls()))
    return apply_overrides(cls(), {k: v for k, v in flat.items() if k in settable}, source="config.json")
