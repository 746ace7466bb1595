"""``remidi evaluate RUN_DIR``: a UED run's trained agents on more evaluation levels.

Every seed of every algorithm in ``RUN_DIR`` (a run, or a several-algorithm run) is reloaded from
its latest ``checkpoint.npz`` and evaluated on

* **the task's own evaluation sets** with ``--attempts`` sampled episodes per level: training's
  metrics for them (``solve_rate/<set>``, ``return/<set>``, ``regret/<set>/...``, ...) and
  ``solve_rate/mean``;
* **CVaR over the level generator** (Rutherford et al. 2024, "No Regrets"): ``--cvar-levels``
  solvable levels drawn with ``--seed`` (the same for every seed and algorithm), ``--cvar-attempts``
  episodes each, twice (SFL's protocol): one set of rollouts ranks the levels, an independent one
  scores them, so ranking luck does not bias the worst levels down. ``cvar/solve_rate/<α>`` and
  ``cvar/return/<α>`` for α ∈ {100%, 10%, 1%}, each only where α of the levels is at least one
  level (else said in one line). Where the task tags levels (``level_tags``):
  ``generator/solve_rate/<tag>``, ``generator/solve_rate/not-<tag>`` (and ``generator/return/...``);
* **larger perfect mazes** (maze experiments): ``--perfect-count`` mazes per side in
  ``--perfect-sizes`` (default 21 and 51), carved by randomised depth-first search from ``--seed``
  (one path between any two cells), agent and goal on random cells, with the exact optimal return.
  Episodes still last at most 250 steps, so ``perfect<S>/reachable`` is the share with a positive
  optimum; ``perfect<S>/solve_rate``, ``perfect<S>/return``, ``perfect<S>/regret``.

The agent samples its actions as in training; ``--action mode`` takes the most likely action
instead and writes ``evaluate-mode.*`` beside the sampled files.

Writes ``RUN_DIR/evaluate.json`` (the run, arguments, code and device
(:func:`remidi.files.code_version`), and per algorithm the checkpoint's update and each metric's
mean, std and per-seed values), ``evaluate.csv`` (algo, seed, metric, value) and ``evaluate.png``.
Every bad argument, or a folder that is not a UED run with a checkpoint, is a one-line error before
anything is computed."""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from remidi.errors import ConfigError, RemidiError
from remidi.envs.perfect_mazes import perfect_mazes
from remidi.files import code_version, writable
from remidi.runs import require_folder

ALPHAS = ((1.0, "100%"), (0.1, "10%"), (0.01, "1%"))  # the mean, then ever further into the tail
DEFAULTS = {"attempts": 10, "cvar_levels": 256, "cvar_attempts": 4, "perfect_sizes": (21, 51), "perfect_count": 16,
            "seed": 0}
MAX_PERFECT_SIZE = 101


@dataclass(frozen=True)
class EvalSettings:
    """What ``remidi evaluate`` evaluates on (its flags of the same names): episodes per
    evaluation-set level, CVaR levels and episodes, the perfect mazes' sides and count, the seed."""

    attempts: int = DEFAULTS["attempts"]
    cvar_levels: int = DEFAULTS["cvar_levels"]
    cvar_attempts: int = DEFAULTS["cvar_attempts"]
    perfect_sizes: tuple[int, ...] = DEFAULTS["perfect_sizes"]
    perfect_count: int = DEFAULTS["perfect_count"]
    seed: int = DEFAULTS["seed"]
    action: str = "sample"

    @property
    def stem(self) -> str:
        return files_stem(self.action)


def files_stem(action: str) -> str:
    """The stem of an evaluation's files: ``evaluate`` (sampled actions) or ``evaluate-mode``."""
    return "evaluate" if action == "sample" else f"evaluate-{action}"


# ------------------------------------------------------------------------------ pure pieces
def cvar(values: np.ndarray, alpha: float, rank_by: np.ndarray | None = None) -> float:
    """The CVaR of the worst ``alpha`` share of levels: the mean of ``values`` f[N] over the
    ``ceil(alpha · N)`` (≥ 1) levels ranking lowest by ``rank_by`` f[N] (ties in level order; None:
    ``values`` itself). SFL ranks on one set of rollouts and scores on another."""
    values = np.asarray(values, dtype=float)
    order = np.argsort(values if rank_by is None else np.asarray(rank_by, dtype=float), kind="stable")
    k = max(1, math.ceil(alpha * len(values) - 1e-9))
    return float(values[order[:k]].mean())


def cvar_shares(num_levels: int) -> list[tuple[float, str]]:
    """The :data:`ALPHAS` with ``α · N ≥ 1`` for ``num_levels`` N: a smaller one would be the single
    worst level, not a CVaR."""
    return [(alpha, label) for alpha, label in ALPHAS if alpha * num_levels + 1e-9 >= 1]


# ------------------------------------------------------------------------------ the command
@dataclass
class _Loaded:
    folder: Path
    algo: str
    seeds: list[int]
    setup: Any
    runner: Any
    update: int
    experiment: str = ""


def _check_args(attempts, cvar_levels, cvar_attempts, perfect_sizes, perfect_count, seed) -> None:
    for key, value in (("--attempts", attempts), ("--cvar-levels", cvar_levels), ("--cvar-attempts", cvar_attempts),
                       ("--perfect-count", perfect_count)):
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise ConfigError(f"{key}: must be an integer ≥ 1, got {value!r}")
    for size in perfect_sizes:
        if isinstance(size, bool) or not isinstance(size, int) or size < 5 or size % 2 == 0 or size > MAX_PERFECT_SIZE:
            raise ConfigError(f"--perfect-sizes: each must be an odd integer in [5, {MAX_PERFECT_SIZE}], got {size!r}")
    from remidi.experiments.base import MAX_SEED

    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"--seed: must be an integer in [0, {MAX_SEED}], got {seed!r}")


def _run_folders(run_dir: Path) -> list[Path]:
    """The run folders of ``run_dir``: itself, or its algorithms' sub-folders in the run's order."""
    from remidi.experiments import outputs

    require_folder("RUN_DIR", run_dir)
    if (run_dir / "config.json").is_file():
        return [run_dir]
    subs = sorted(p for p in run_dir.iterdir() if (p / "config.json").is_file())
    if not subs:
        raise ConfigError(f"RUN_DIR: {run_dir} holds no run (no config.json in it or its sub-folders)")
    try:
        order = outputs.read_json(subs[0] / "config.json").get("algos") or []
    except (OSError, ValueError, AttributeError):
        order = []  # _load reports an unreadable config.json
    return sorted(subs, key=lambda p: (order.index(p.name) if p.name in order else len(order), p.name))


def _load(folder: Path, task=None) -> _Loaded:
    """The run in ``folder`` with its agent restored from the checkpoint (seed axis first) and its
    task rebuilt from config.json, or ``task`` where given. ConfigError (one line) for a run that is
    no UED run or has no readable checkpoint."""
    from remidi.engine.run import driver
    from remidi.engine import train as tr
    from remidi.engine.run.checkpoint import CHECKPOINT
    from remidi.experiments import saved_experiment
    from remidi.experiments.resuming import saved_run

    if task is None:
        lookup = saved_experiment
    else:
        from remidi.experiments.custom import task_experiment

        def lookup(name, _record=None):
            return task_experiment(name, lambda: task)

    exp, algo, _, seeds, config = saved_run(lookup, folder, flag="RUN_DIR")
    if exp.make_task is None:
        raise ConfigError(f"RUN_DIR: {folder} is a {exp.name} run; evaluate needs a UED run (a trained agent)")
    path = folder / CHECKPOINT
    if not path.is_file():
        raise ConfigError(f"RUN_DIR: {folder} has no {CHECKPOINT} (the run wrote no checkpoint yet)")
    setup = tr.make_setup(exp.make_task(config), config, algo)
    runner, meta = driver.load_run_state(setup, seeds, path, flag="RUN_DIR")
    return _Loaded(folder=folder, algo=algo, seeds=list(seeds), setup=setup, runner=runner,
                   update=int(meta.get("done", -1)), experiment=exp.name)


def _solvable_levels(task, count: int, seed: int):
    """``count`` generator levels drawn with ``seed``, leaving out those with optimal return ≤ 0
    (which would sit at the bottom of every CVaR), in at most 64 rounds (fewer where solvable levels
    are rare)."""
    import jax

    keys = jax.random.split(jax.random.PRNGKey(seed), 64)
    sample = jax.jit(jax.vmap(task.sample_level))
    optimum = jax.jit(jax.vmap(task.optimal_return)) if task.optimal_return is not None else None
    kept, total = [], 0
    for key in keys:
        batch = sample(jax.random.split(key, count))
        if optimum is not None:
            solvable = np.asarray(optimum(batch)) > 0
            batch = jax.tree.map(lambda x: x[solvable], batch)
        kept.append(batch)
        total += int(jax.tree.leaves(batch)[0].shape[0])
        if total >= count:
            break
    levels = jax.tree.map(lambda *xs: np.concatenate(xs)[:count], *kept)
    if total == 0:
        raise ConfigError("--cvar-levels: the task's generator made no solvable level in 64 rounds")
    return levels


def _metrics_fn(setup, settings: EvalSettings, cvar_levels, perfect: dict):
    """A jitted ``(runner [S, ...], keys [S]) -> {metric: f32[S, ...]}`` of a run's raw
    evaluations, the agent acting by ``settings.action``: the evaluation sets as training evaluates
    them, ``[S]``; CVaR's per-level solve rates and returns ``[S, N]``; per perfect size returns ``[S, L]``."""
    import dataclasses

    import jax
    import jax.numpy as jnp

    from remidi.engine.adversaries.scores import episode_solved
    from remidi.engine.run import evaluation
    from remidi.engine import train as tr

    task, attempts, cvar_attempts, action = setup.task, settings.attempts, settings.cvar_attempts, settings.action
    held_out = tr.make_setup(task, dataclasses.replace(setup.cfg, eval_attempts=attempts), setup.algo)

    def one_seed(runner, key):
        out = dict(evaluation.evaluate(held_out, runner, key, action))
        # CVaR: one set of rollouts ranks the levels, an independent one (other keys) scores them
        for part, salt in (("rank", 1000), ("score", 1001)):
            ret, _, flags = evaluation.level_episodes(setup, runner, task.env, cvar_levels, cvar_attempts,
                                                      jax.random.fold_in(key, salt), action)
            out[f"cvar_raw/{part}/return"] = ret.mean(axis=1)
            if task.solved is not None:
                solved = episode_solved(task.solved, ret, flags)
                out[f"cvar_raw/{part}/solve_rate"] = solved.astype(jnp.float32).mean(axis=1)
        for size, (env, levels) in perfect.items():
            ret, _ = evaluation.level_returns(setup, runner, env, levels, attempts, jax.random.fold_in(key, 2000 + size),
                                              action)
            out[f"perfect_raw/{size}"] = ret  # [L, attempts]
        return out

    return jax.jit(jax.vmap(one_seed))


def _summarise(raw: dict[str, np.ndarray], setup, perfect_optimal: dict[int, np.ndarray],
               tags: dict[str, np.ndarray] | None = None) -> dict[str, np.ndarray]:
    """Per-seed metrics f[S] from the raw evaluations; ``tags``: the CVaR levels' tags
    (``task.level_tags``, bool[N] each) for ``generator/<kind>/<tag>``."""
    task = setup.task
    out = {name: np.asarray(v, float) for name, v in raw.items() if not name.startswith(("cvar_raw/", "perfect_raw/"))}
    rates = [name for name in out if name.startswith("solve_rate/")]
    if len(rates) > 1:
        out["solve_rate/mean"] = np.mean([out[name] for name in rates], axis=0)
    for kind in ("solve_rate", "return"):
        if f"cvar_raw/score/{kind}" in raw:
            ranking = np.asarray(raw[f"cvar_raw/rank/{kind}"], float)  # [S, N]
            scoring = np.asarray(raw[f"cvar_raw/score/{kind}"], float)  # [S, N], independent episodes
            for alpha, label in cvar_shares(scoring.shape[1]):
                out[f"cvar/{kind}/{label}"] = np.array([cvar(v, alpha, r) for v, r in zip(scoring, ranking)])
            for tag, tagged in (tags or {}).items():  # the generator's levels of one kind alone
                if tagged.any():
                    out[f"generator/{kind}/{tag}"] = scoring[:, tagged].mean(axis=1)
                if (~tagged).any():
                    out[f"generator/{kind}/not-{tag}"] = scoring[:, ~tagged].mean(axis=1)
    for size, optimal in perfect_optimal.items():
        returns = np.asarray(raw[f"perfect_raw/{size}"], float)  # [S, L, attempts]
        if task.solved is not None:
            out[f"perfect{size}/solve_rate"] = np.asarray(task.solved(returns), float).mean(axis=(1, 2))
        out[f"perfect{size}/return"] = returns.mean(axis=(1, 2))
        out[f"perfect{size}/regret"] = (optimal[None, :] - returns.mean(axis=2)).mean(axis=1)
        out[f"perfect{size}/reachable"] = np.full(returns.shape[0], float(np.mean(optimal > 0)))
    return out


def evaluate_run(run_dir, settings: EvalSettings = EvalSettings(), *, log: Callable[[str], None] | None = None,
                 task=None) -> dict:
    """Evaluate every algorithm and seed in ``run_dir`` on ``settings`` and write ``evaluate.json``,
    ``evaluate.csv`` and ``evaluate.png`` there (``evaluate-mode.*`` with ``action="mode"``); returns
    the JSON document. ``task``: the run's :class:`~remidi.envs.interface.UEDTask` where
    ``config.json`` cannot rebuild it (``run_ued`` without ``task_ref``)."""
    import jax

    from remidi.envs.maze import MazeEnv, optimal_return
    from remidi.experiments import outputs

    attempts, cvar_levels, cvar_attempts = settings.attempts, settings.cvar_levels, settings.cvar_attempts
    perfect_sizes, perfect_count, seed = settings.perfect_sizes, settings.perfect_count, settings.seed
    _check_args(attempts, cvar_levels, cvar_attempts, tuple(perfect_sizes), perfect_count, seed)
    from remidi.engine.core.distributions import acting

    acting(None, settings.action)  # a one-line error for an unknown --action, before anything is loaded
    run_dir = Path(run_dir)
    folders = _run_folders(run_dir)
    if not writable(run_dir):  # before minutes of evaluation whose results could not be written
        raise ConfigError(f"RUN_DIR: {run_dir} is not writable: evaluate writes evaluate.json, evaluate.csv and "
                          f"evaluate.png there; evaluate a writable copy of the run")
    loaded = [_load(folder, task) for folder in folders]  # every run checked before any is evaluated
    args = {"attempts": attempts, "cvar_levels": cvar_levels, "cvar_attempts": cvar_attempts,
            "perfect_sizes": list(perfect_sizes), "perfect_count": perfect_count, "seed": seed,
            "action": settings.action}
    doc: dict[str, Any] = {"run": str(run_dir), "experiment": loaded[0].experiment, "args": args,
                           "code": code_version(), "algorithms": {}}  # code: the commit and device it ran on
    rows = []
    cvar_sets: dict[Any, Any] = {}  # task → its CVaR levels and their tags: the algorithms of one run share them
    mazes: dict[int, tuple] = {}  # size → (env, perfect mazes, their optimal returns), built once
    if any(isinstance(run.setup.task.env, MazeEnv) for run in loaded):
        optimum = jax.jit(jax.vmap(optimal_return))
        for size in perfect_sizes:
            batch = perfect_mazes(size, perfect_count, seed)
            mazes[size] = (MazeEnv(size), batch, np.asarray(optimum(batch), float))
    for run in loaded:
        task = run.setup.task
        if task not in cvar_sets:
            batch = _solvable_levels(task, cvar_levels, seed)
            cvar_sets[task] = batch, {name: np.asarray(t, bool) for name, t in jax.vmap(task.level_tags)(batch).items()}
            count = int(jax.tree.leaves(batch)[0].shape[0])
            left_out = [(alpha, label) for alpha, label in ALPHAS if (alpha, label) not in cvar_shares(count)]
            if left_out and log is not None:
                log(f"CVaR at {', '.join(label for _, label in left_out)} left out: of {count} levels that share is "
                    f"less than one level (the single worst one); --cvar-levels "
                    f"{math.ceil(1 / left_out[-1][0] - 1e-9)} or more reports it")
        levels, tags = cvar_sets[task]
        is_maze = isinstance(task.env, MazeEnv)
        perfect = {size: (env, batch) for size, (env, batch, _) in mazes.items()} if is_maze else {}
        optimal = {size: opt for size, (_, _, opt) in mazes.items()} if is_maze else {}
        if log is not None:
            total = run.setup.cfg.num_updates
            log(f"evaluating {run.folder} ({run.algo}, {len(run.seeds)} seed{'s' if len(run.seeds) != 1 else ''}, "
                f"checkpoint of update {run.update} of {total}{'' if run.update >= total else ': unfinished'})")
        keys = jax.vmap(jax.random.PRNGKey)(np.asarray(run.seeds, np.uint32) + np.uint32(seed))
        raw = jax.device_get(_metrics_fn(run.setup, settings, levels, perfect)(run.runner, keys))
        metrics = _summarise(raw, run.setup, optimal, tags)
        doc["algorithms"][run.algo] = {"folder": str(run.folder), "seeds": run.seeds, "update": run.update,
                                       "num_updates": run.setup.cfg.num_updates,
                                       # fewer than --cvar-levels where the generator rarely makes a solvable one
                                       "cvar_levels_used": int(jax.tree.leaves(levels)[0].shape[0]),
                                       "metrics": outputs.summarize(metrics)}
        rows += [(run.algo, s, name, float(values[i])) for name, values in metrics.items()
                 for i, s in enumerate(run.seeds)]
    outputs.write_json(run_dir / f"{settings.stem}.json", doc)

    def write_csv(fh):
        w = csv.writer(fh)
        w.writerow(["algo", "seed", "metric", "value"])
        for row in rows:
            w.writerow([*row[:3], repr(row[3])])

    outputs.atomic_write(run_dir / f"{settings.stem}.csv", write_csv)
    _plot(run_dir / f"{settings.stem}.png", doc)
    return doc


def _plot(path: Path, doc: dict) -> None:
    """Bars per algorithm (mean ± std over seeds) of the solve-rate metrics (returns where the task
    has no solve criterion)."""
    from remidi.experiments.plots import plot_bars

    algos = doc["algorithms"]
    names = list(next(iter(algos.values()))["metrics"])
    kind = "solve_rate" if any("solve_rate" in n for n in names) else "return"
    shown = [n for n in names if n.split("/")[0] == kind or n.startswith("cvar/" + kind)
             or (n.startswith("perfect") and n.endswith("/" + kind))]
    series = {algo: np.array([entry["metrics"][n]["per_seed"] for n in shown], float) for algo, entry in algos.items()}
    run = Path(doc["run"])
    name = str(run) if len(run.parts) <= 2 else str(Path(*run.parts[-2:]))  # e.g. tmaze/20261124-2338
    updates = sorted({entry["update"] for entry in algos.values()})
    at = f", update {updates[0]}" if len(updates) == 1 else ""
    unfinished = any(entry["update"] < entry.get("num_updates", entry["update"]) for entry in algos.values())
    which = "last checkpoint (unfinished)" if unfinished else "final checkpoint"
    if doc["args"].get("action", "sample") != "sample":
        which += f", actions: the policy's {doc['args']['action']}"
    plot_bars(path, f"{doc.get('experiment') or 'run'}: {kind.replace('_', ' ')} of {name}'s {which}{at}",
              shown, series, kind, ylim=(0.0, 1.0) if kind == "solve_rate" else None)


def main_args(parser) -> None:
    """The ``remidi evaluate`` arguments (added to the CLI's sub-parser)."""
    parser.add_argument("run_dir", metavar="RUN_DIR", help="a run folder, or a several-algorithm run's folder")
    parser.add_argument("--attempts", type=int, default=DEFAULTS["attempts"],
                        help=f"episodes per level of the task's evaluation sets and the perfect mazes "
                             f"(default {DEFAULTS['attempts']})")
    parser.add_argument("--cvar-levels", type=int, default=DEFAULTS["cvar_levels"],
                        help=f"levels drawn from the task's generator for CVaR (default {DEFAULTS['cvar_levels']})")
    parser.add_argument("--cvar-attempts", type=int, default=DEFAULTS["cvar_attempts"],
                        help=f"episodes per CVaR level (default {DEFAULTS['cvar_attempts']})")
    parser.add_argument("--perfect-sizes", default=",".join(map(str, DEFAULTS["perfect_sizes"])),
                        help="sides of the perfect mazes, comma-separated odd numbers (maze runs; default 21,51)")
    parser.add_argument("--perfect-count", type=int, default=DEFAULTS["perfect_count"],
                        help=f"perfect mazes per size (default {DEFAULTS['perfect_count']})")
    parser.add_argument("--action", metavar="{sample,mode}", default="sample",
                        help="sample: actions drawn from the policy (default, as it trained); mode: its most likely "
                             "action each step (a Gaussian's mean), written to evaluate-mode.*")
    parser.add_argument("--seed", type=int, default=DEFAULTS["seed"],
                        help="draws the CVaR levels and perfect mazes (the same for every run) and the episodes")


def run_from_args(args) -> dict:
    try:
        sizes = tuple(int(x) for x in str(args.perfect_sizes).split(",") if x.strip())
    except ValueError:
        raise RemidiError(f"--perfect-sizes: must be comma-separated odd integers, got {args.perfect_sizes!r}") from None
    import sys

    settings = EvalSettings(attempts=args.attempts, cvar_levels=args.cvar_levels, cvar_attempts=args.cvar_attempts,
                            perfect_sizes=sizes, perfect_count=args.perfect_count, seed=args.seed, action=args.action)
    return evaluate_run(args.run_dir, settings, log=lambda line: print(line, file=sys.stderr, flush=True))
