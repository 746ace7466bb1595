"""The tabular UED experiment (paper §6.2, Figures 3–5): ``tabular-distinct`` and ``tabular-shared``.

MMR-UED (one adversary) and ReMiDi (adversaries with the exact multi-policy ``Combine``) on the
paper's six-level game with exact expected regret, against the exact BLP solution
(:mod:`remidi.solvers.onestep`)."""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from remidi.errors import ConfigError, choice, non_negative, positive, positive_int, probability, require
from remidi.experiments.base import Experiment, RunContext, RunResult
from remidi.experiments.plots import MEAN_STD, REFERENCE_STYLE, Curve, Panel, plot_panels, run_title, series_style
from remidi.solvers.onestep import OneStepGame, solve_blp
from remidi.tabular.games import paper_game
from remidi.tabular.learner import TabularUEDConfig, train

ALGORITHMS = ("mmr", "remidi")
PRESETS = {
    "paper": {},
    "smoke": {"iterations": 1500, "iters_per_adversary": 500},
}
PRESET_SEEDS = {"paper": 50, "smoke": 10}


def validate(cfg: TabularUEDConfig, algo: str) -> None:
    choice("--algo", algo, ALGORITHMS)
    positive_int("iterations", cfg.iterations)
    positive_int("log_every", cfg.log_every)
    if cfg.log_every > cfg.iterations:
        raise ConfigError(f"log_every: must be ≤ iterations ({cfg.iterations}), got {cfg.log_every}; "
                          f"lower log_every or raise iterations")
    require(cfg.adversary_updates >= 0, "adversary_updates", "an integer ≥ 0", cfg.adversary_updates)
    require(cfg.agent_updates >= 0, "agent_updates", "an integer ≥ 0", cfg.agent_updates)
    positive("policy_lr", cfg.policy_lr)
    require(0 < cfg.value_lr <= 1, "value_lr", "in (0, 1]", cfg.value_lr)
    non_negative("agent_entropy", cfg.agent_entropy)
    non_negative("adversary_entropy", cfg.adversary_entropy)
    probability("gamma", cfg.gamma)
    choice("optimizer", cfg.optimizer, ("adam", "sgd"))
    require(0 <= cfg.adam_b1 < 1, "adam_b1", "in [0, 1)", cfg.adam_b1)
    non_negative("init_scale", cfg.init_scale)
    positive_int("num_adversaries", cfg.num_adversaries)
    positive_int("iters_per_adversary", cfg.iters_per_adversary)
    require(0 < cfg.support_threshold <= 1, "support_threshold", "in (0, 1]", cfg.support_threshold)
    if algo == "remidi":
        needed = (cfg.num_adversaries - 1) * cfg.iters_per_adversary
        if needed >= cfg.iterations:
            raise ConfigError(
                f"num_adversaries: must be small enough that the last adversary gets iterations, but "
                f"(num_adversaries − 1) × iters_per_adversary = ({cfg.num_adversaries} − 1) × "
                f"{cfg.iters_per_adversary} = {needed} is not below iterations = {cfg.iterations}; lower "
                f"num_adversaries or iters_per_adversary, or raise iterations")


def reference(game: OneStepGame) -> dict:
    """Exact MMR value and BLP regret per observation from the LP solver."""
    exact = solve_blp(game)
    level_regret = np.asarray(exact.regret)
    obs = game.observation_index()
    blp = {name: float(level_regret[obs == o].max()) for o, name in enumerate(game.observation_names)}
    return {"mmr_value": float(exact.mmr_value), "blp_regret": blp,
            "rounds": [{"value": float(r.value), "support": list(r.support)} for r in exact.rounds]}


def make_train(setting: str):
    def train_tabular(ctx: RunContext) -> RunResult:
        game = paper_game(setting)
        cfg: TabularUEDConfig = ctx.config
        validate(cfg, ctx.algo)  # the same rules as run_experiment, for direct callers
        num_pairs = 1 if ctx.algo == "mmr" else cfg.num_adversaries
        _, hist = train(ctx.seeds, game, cfg, num_pairs)
        history: dict[str, np.ndarray] = {}
        for o, obs in enumerate(game.observation_names):
            history[f"regret/{obs}"] = hist["regret"][..., o]
        history["regret/max"] = hist["regret"].max(axis=-1)
        for level, name in enumerate(game.level_names):
            history[f"adversary_prob/{name}"] = hist["adversary_prob"][..., level]
        for o, obs in enumerate(game.observation_names):
            for a, action in enumerate(game.actions):
                history[f"policy/{obs}/{action}"] = hist["policy"][..., o, a]
        history["adversary_index"] = hist["stage"].astype(float)
        extra = {"reference": reference(game), "num_adversaries": num_pairs}
        return RunResult(steps=hist["steps"], history=history, extra=extra)

    return train_tabular


def plot(folder: Path, results: dict[str, RunResult], cfg: TabularUEDConfig, preset: str | None = None,
         seeds: list[int] | None = None, experiment: str = "") -> None:
    """``regret.png`` (greatest regret per observation, exact BLP regrets dashed) and
    ``adversary.png`` (level probabilities), one panel per algorithm, mean ± std over seeds. Colours
    are fixed per observation or level; coinciding curves are drawn once, labelled together."""
    any_result = next(iter(results.values()))
    blp = any_result.extra["reference"]["blp_regret"]
    by_value: dict[float, list[str]] = {}
    for obs, value in blp.items():
        by_value.setdefault(round(value, 6), []).append(obs)
    label = "exact BLP: " + ", ".join(f"{v:g} ({', '.join(obs)})" for v, obs in sorted(by_value.items()))
    refs = [(v, label) for v in sorted(by_value)]  # one legend entry for all of them
    regret_panels, adversary_panels = [], []
    for algo, result in results.items():
        names = [name for name in result.history if name.startswith("regret/") and name != "regret/max"]
        # h1 and h3 both end at 0.175 under BLP: each observation its own line style and marker
        regret_curves = [Curve(f"observation {name.split('/', 1)[1]}", result.steps, result.history[name],
                               series_style(i)) for i, name in enumerate(names)]
        regret_panels.append(Panel(f"{algo}: greatest regret per observation", regret_curves,
                                   "greatest regret over the observation's levels", "iteration", refs))
        levels = [name for name in result.history if name.startswith("adversary_prob/")]
        adversary_curves = [Curve(name.split("/", 1)[1], result.steps, result.history[name],
                                  {"color": series_style(i)["color"]}) for i, name in enumerate(levels)]
        adversary_panels.append(Panel(f"{algo}: adversary level probabilities", adversary_curves,
                                      "probability the adversary samples the level", "iteration",
                                      ylim=(0.0, 1.0), merge_coinciding=True))
    title = run_title(experiment, preset, seeds)
    plot_panels(folder / "regret.png", regret_panels, title=title,
                caption=f"{MEAN_STD}; {REFERENCE_STYLE}: the exact BLP solution's greatest regret per observation")
    plot_panels(folder / "adversary.png", adversary_panels, title=title,
                caption=f"{MEAN_STD}; a line for several levels is dashed in each level's colour")


def _experiment(setting: str) -> Experiment:
    return Experiment(
        name=f"tabular-{setting}",
        description=f"paper §6.2: six-level one-step game, '{setting}' observations; exact expected regret",
        algorithms=ALGORITHMS,
        config_factory=TabularUEDConfig,
        presets=PRESETS,
        preset_seeds=PRESET_SEEDS,
        validate=validate,
        train=make_train(setting),
        plot=partial(plot, experiment=f"tabular-{setting}"),
        scaled_keys={"iterations": ("log_every", "iters_per_adversary")},
    )


EXPERIMENTS = [_experiment("distinct"), _experiment("shared")]
