"""``remidi bench``: named, rerunnable throughput benchmarks.

The package: :mod:`~remidi.bench.registry` (the registry and the settings a benchmark process
reads), :mod:`~remidi.bench.workloads` (what each benchmark compiles) and
:mod:`~remidi.bench.runner` (timing each in its own process, lanes, ratios, the table).

Each benchmark builds one compiled program, times its compilation (``compile_s``), warms it up,
then times ``repeats`` calls (``block_until_ready``) and reports the median
(``env_steps_per_s``, ``seconds_per_call``) and the process's peak resident memory
(``peak_rss_mb``). Every benchmark runs in a fresh Python process, so its memory and compile
time are its own; ratios are taken between benchmarks of one ``remidi bench`` invocation (same
machine, same moment).

Workloads (one seed, or ``--seeds N`` trained together as a run of N seeds does; the shapes of the
paper's maze preset; the train steps are the engine's own ``train_step`` inside the driver's
compiled block, ``driver.run_steps``):

* ``maze-plr``: PLR⊥ on the T-maze task, 32 envs × 256 steps, the paper's maze agent (conv +
  LSTM), PPO 5 epochs × 1 minibatch; the buffer (4000) is full and every update replays, so
  every update is one rollout plus a gradient update (as in jaxued's maze PLR example).
* ``maze-remidi``: the same for ReMiDi in its last buffer, three full frozen buffers of 256
  task levels (half of them T-mazes) tracked by the candidate tracker; reports the tracker's
  overflow.
* ``nomatch-plr``, ``nomatch-remidi``: ``maze-plr`` and ``maze-remidi`` on the fogged maze
  (:mod:`~remidi.bench.nomatch`: ordinary mazes whose every level carries a diffusing fog field
  of its own, so no two levels share a first observation, and 32 stencil substeps make a step
  costlier than the maze's), where ReMiDi's tracker matches nothing: ``nomatch_remidi_step_over_plr_step`` is what
  ReMiDi costs where it masks nothing (not run by default).
* ``maze-remidi-reference``: ``maze-remidi`` with the reference tracker (every frozen level
  stepped beside every env), for the ratio of the two trackers (not run by default: slow).
* ``maze-remidi-combine``: ``maze-remidi`` with ``remidi.policy=combine`` (Algorithm 1's
  multi-policy form: the three frozen buffers' policies each read every step's observation and
  the earliest buffer whose levels explain the prefix acts); ``remidi_combine_step_over_remidi_step``
  (not run by default).
* ``maze-remidi-rehearsal``: ``maze-remidi`` with ``remidi.rehearsal=1``: every update trains on
  a batch of a frozen buffer's levels instead of a replay of the active one (one rollout and one
  PPO update either way); ``remidi_rehearsal_step_over_remidi_step`` (not run by default).
* ``maze-remidi-belief``: ``maze-remidi`` with the learned belief tracker
  (``remidi.tracker=belief``, engine/trackers/belief.py): each step every env's prefix is scored by the
  three frozen buffers' GRU models instead of stepping frozen levels, and the active buffer's
  model fits on every replay (``remidi.belief_epochs`` updates);
  ``remidi_belief_step_over_remidi_step`` is its cost per environment step against the exact
  candidate tracker's (not run by default).
* ``maze-remidi-simulated``: ``maze-remidi`` with the simulated belief model
  (``remidi.tracker=simulated`` judged by the ratio, engine/trackers/simulated.py): each step every env's
  ``tracker_budget`` candidates are stepped in two copies, and every update replays its levels
  twice for the noise table (and a fresh update fits the GRU reference);
  ``remidi_simulated_step_over_remidi_step`` (not run by default).
* ``maze-accel``: ACCEL (``accel``) on the same set-up as ``maze-plr``: with every update
  replaying, the updates alternate between a replay (rollout + PPO) and an edit of that replay's
  levels (rollout + scoring + insertion, no PPO); reports the share of edit updates (``edit``)
  and no GFLOP/s (the network's count assumes every update trains).
* ``maze-paired``: PAIRED (``paired``) on the same set-up as ``maze-plr``: every update the
  generator builds 32 levels (29 design steps each, its 64-unit MLP), the protagonist rolls out
  and learns as PLR⊥'s replay update does, the antagonist rolls out and learns, and the
  generator learns; ``paired_step_over_plr_step`` is its cost per environment step against
  ``maze-plr``'s (no GFLOP/s: the count covers one network).
* ``maze-paired-reference``: ``maze-paired`` with the reference libraries' generator
  (``paired.generator_network=reference``: a 128-channel conv, a 256-unit LSTM);
  ``paired_reference_step_over_plr_step`` (not run by default).
* ``maze-env``: the maze environment alone (random actions, 32 envs × 256 steps, automatic
  restarts): the ceiling training cannot beat.
* ``lever-plr``: PLR⊥ on the lever game's paper preset, every update replaying.
* ``lever-sfl``: SFL (``sfl``) on the same preset, ``sfl.refresh_every`` = 25 updates per call,
  the first of them refreshing the buffer (1024 candidate levels played 32 steps each by the
  current policy, no gradient), each update training on 16 buffer and 16 fresh levels;
  ``sfl_update_over_plr_update`` is its time per update (the refresh amortised) against
  ``lever-plr``'s, both trained every update (not run by default).
* ``lstm-matmul``: the maze LSTM's gate product alone, chained: the rate (``gflops_per_s``)
  this machine reaches on the shape that dominates maze training. Training workloads report
  their network's ``gflops_per_s`` too (XLA's operation count), so ``maze_plr_flops_over_matmul``
  says how far ``maze-plr`` is from it.
* ``solve-onestep``: ``remidi solve``'s exact BLP of a random one-step game of 10,000 levels,
  100 observations and 3 actions (rewards uniform in [0, 1], seed 0); plain Python and HiGHS, no
  compilation (not run by default).
* ``tracker-maze-plr``, ``tracker-maze-remidi-{0,8,64}``, ``tracker-brax-plr``,
  ``tracker-brax-remidi-{8,64}``: the exact tracker's cost per environment step against
  ``remidi.tracker_budget``, fresh-level updates only (:mod:`~remidi.bench.tracker_cost`; not run
  by default).
* ``brax-plr``: PLR⊥ on ``brax-hopper``'s paper preset (256 envs × 100 steps, PPO 4 epochs × 32
  minibatches, the 256-unit LSTM agent), every update replaying (not run by default: about 4 s
  per update on a 2-core CPU, docs/performance.md).
"""

from remidi.bench import tracker_cost, workloads  # noqa: F401  (registers every benchmark)
from remidi.bench.registry import BENCHMARKS, DEFAULT, check_overrides
from remidi.bench.runner import format_table, run_benchmarks

__all__ = ["BENCHMARKS", "DEFAULT", "check_overrides", "format_table", "run_benchmarks"]
