"""Logging a run to Weights & Biases and TensorBoard: ``remidi run ... --log wandb,tensorboard``.

Each algorithm's run folder becomes one tracked run per backend:

* **Weights & Biases** (``pip install "remidi[wandb]"``): one W&B run per algorithm (named
  ``<experiment>/<algo>``, grouped by the output folder, in project ``$WANDB_PROJECT`` or
  ``remidi``), its files under ``<folder>/wandb``
  (``WANDB_MODE=offline`` works and keeps everything there; sync later with ``wandb sync``).
* **TensorBoard** (``pip install "remidi[tensorboard]"``, tensorboardX): event files under
  ``<folder>/tensorboard/seed_<s>``, one writer per seed, so TensorBoard overlays the seeds.

What is logged: the full run configuration (config.json) as hyper-parameters; every metric of
``metrics.csv`` per seed (W&B keys ``seed_<s>/<metric>``; TensorBoard tags ``<metric>`` in each
seed's directory) as each block of ``eval_every`` updates finishes (UED experiments) or at the end
(tabular games); the final summary (means over seeds); the run's PNG plots at the end. A run
resumed with ``--resume`` continues the same tracked run (the W&B id and the last logged step are
kept in ``<folder>/tracking.json``), without logging a step twice.
"""

from __future__ import annotations

import importlib.util
import json
import math
import netrc
import os
import uuid
from pathlib import Path
from typing import Any

import numpy as np

from remidi.errors import ConfigError

BACKENDS = {"wandb": ("wandb", "remidi[wandb]"), "tensorboard": ("tensorboardX", "remidi[tensorboard]")}
STATE = "tracking.json"


def parse_log(text: str | None) -> list[str]:
    """``"wandb,tensorboard"`` → the backends, checked: each known and its package installed
    (ConfigError, one line naming the extra to install, otherwise)."""
    if not text:
        return []
    names = [name.strip() for name in text.split(",")]
    if not all(names):
        raise ConfigError(f"--log: {text!r} has an empty name; allowed: {', '.join(BACKENDS)}")
    for name in names:
        if name not in BACKENDS:
            raise ConfigError(f"--log: unknown value {name!r}; allowed: {', '.join(BACKENDS)}")
        module, extra = BACKENDS[name]
        if importlib.util.find_spec(module) is None:
            raise ConfigError(f'--log: {name} needs the {module} package: pip install "{extra}"')
        if name == "wandb" and not _wandb_can_log():
            raise ConfigError("--log: wandb has no API key here (wandb login, or WANDB_API_KEY); or log without "
                              "an account: WANDB_MODE=offline (files stay in the run folder; wandb sync uploads them)")
    return list(dict.fromkeys(names))


def _wandb_can_log() -> bool:
    """W&B will not stop at its login: it runs offline or disabled, or an API key is set (in the
    environment or in ~/.netrc, where ``wandb login`` puts it)."""
    if os.environ.get("WANDB_MODE", "").lower() in ("offline", "disabled", "dryrun") or os.environ.get("WANDB_API_KEY"):
        return True
    try:
        hosts = netrc.netrc().hosts
    except (OSError, netrc.NetrcParseError):
        return False
    return any("wandb" in host for host in hosts)


class RunLogger:
    """The tracked runs of one algorithm's run folder (every backend in ``backends``)."""

    def __init__(self, backends: list[str], folder: Path, name: str, config_doc: dict, seeds: list[int],
                 group: str = ""):
        from remidi.experiments.outputs import read_json

        self.folder, self.seeds = Path(folder), list(seeds)
        state_path = self.folder / STATE
        self.state: dict[str, Any] = read_json(state_path) if state_path.exists() else {}
        self.last_step = int(self.state.get("last_step", -1))
        self._wandb = self._writers = None
        if "wandb" in backends:
            import wandb

            run_id = self.state.get("wandb_id") or uuid.uuid4().hex[:8]
            self.state["wandb_id"] = run_id
            self._wandb = wandb.init(project=os.environ.get("WANDB_PROJECT", "remidi"), name=name, group=group or None,
                                     id=run_id, resume="allow", dir=str(self.folder), config=config_doc,
                                     settings=wandb.Settings(silent=True, console="off"))
        if "tensorboard" in backends:
            from tensorboardX import SummaryWriter

            # tensorboardX names an event file by the second it opened it: a part resumed within the same
            # second as the one before (a short run, programs from the compilation cache) would overwrite
            # that part's file, so each part's files get a suffix of their own
            part = f".part{uuid.uuid4().hex[:8]}"
            self._writers = {s: SummaryWriter(logdir=str(self.folder / "tensorboard" / f"seed_{s}"), filename_suffix=part)
                             for s in seeds}
            if self.last_step < 0:  # once per tracked run
                text = "```\n" + json.dumps(config_doc, indent=2) + "\n```"
                for writer in self._writers.values():
                    writer.add_text("config", text, 0)
        self._save_state()

    def _save_state(self) -> None:
        from remidi.experiments.outputs import write_json

        write_json(self.folder / STATE, {**self.state, "last_step": self.last_step})

    def log(self, step: int, metrics: dict[str, np.ndarray]) -> None:
        """Log ``metrics`` ({name: f[S]}, one value per seed) at ``step``; steps already logged
        (before a resume) are skipped."""
        if step <= self.last_step:
            return
        values = {name: np.asarray(v, float).reshape(-1) for name, v in metrics.items()}
        if self._wandb is not None:
            row = {f"seed_{s}/{name}": float(v[i]) for name, v in values.items() for i, s in enumerate(self.seeds)
                   if math.isfinite(v[i])}
            self._wandb.log(row, step=int(step))
        if self._writers is not None:
            for i, s in enumerate(self.seeds):
                for name, v in values.items():
                    if math.isfinite(v[i]):
                        self._writers[s].add_scalar(name, float(v[i]), int(step))
                self._writers[s].flush()
        self.last_step = int(step)
        self._save_state()

    def log_history(self, steps, history: dict[str, np.ndarray]) -> None:
        """Log a whole history ({name: f[S, T]} at ``steps`` [T]) step by step (what was not streamed)."""
        for t, step in enumerate(steps):
            self.log(int(step), {name: np.asarray(v)[:, t] for name, v in history.items()})

    def finish(self, summary: dict, plots: list[Path]) -> None:
        """The final summary (means over seeds) and the plots, then close every backend."""
        means = {name: m["mean"] for name, m in summary.get("metrics", {}).items()
                 if isinstance(m.get("mean"), float) and math.isfinite(m["mean"])}
        if self._wandb is not None:
            import wandb

            self._wandb.summary.update({f"final/{k}": v for k, v in means.items()})
            images = {f"plots/{p.stem}": wandb.Image(str(p)) for p in plots if p.exists()}
            if images:
                self._wandb.log(images, step=max(self.last_step, 0))
            self._wandb.finish()
            wandb.teardown()  # stop W&B's service process: it would outlive the run holding our stdout open
        if self._writers is not None:
            import matplotlib.image

            text = "\n".join(f"{k}: {v:.6g}" for k, v in means.items())
            for s, writer in self._writers.items():
                writer.add_text("summary", text, max(self.last_step, 0))
                if s == self.seeds[0]:
                    for p in plots:
                        if p.exists():
                            image = matplotlib.image.imread(str(p))[..., :3]
                            writer.add_image(f"plots/{p.stem}", image, max(self.last_step, 0), dataformats="HWC")
                writer.close()
        self.state["finished"] = True
        self._save_state()

    def close(self) -> None:
        """Flush and close every backend after an interruption (the run continues on resume)."""
        if self._wandb is not None:
            import wandb

            self._wandb.finish(exit_code=1)
            wandb.teardown()
            self._wandb = None
        if self._writers is not None:
            for writer in self._writers.values():
                writer.close()
            self._writers = None
