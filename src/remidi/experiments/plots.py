"""Plots: panels of training curves, mean ± std over seeds."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


@dataclass
class Curve:
    """One line: ``values`` f[S, T] over seeds and log points, drawn as mean ± std."""

    label: str
    steps: np.ndarray
    values: np.ndarray


@dataclass
class Panel:
    title: str
    curves: list[Curve]
    ylabel: str = ""
    xlabel: str = "step"
    references: list[tuple[float, str]] = field(default_factory=list)  # dashed horizontal lines


def plot_panels(path: Path, panels: list[Panel], title: str = "") -> None:
    """Save ``panels`` side by side into the PNG ``path``."""
    fig, axes = plt.subplots(1, len(panels), figsize=(5.2 * len(panels), 4.0), squeeze=False)
    colors = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for ax, panel in zip(axes[0], panels):
        for i, curve in enumerate(panel.curves):
            values = np.asarray(curve.values, dtype=float)
            mean, std = values.mean(axis=0), values.std(axis=0)
            color = colors[i % len(colors)]
            ax.plot(curve.steps, mean, label=curve.label, color=color)
            ax.fill_between(curve.steps, mean - std, mean + std, color=color, alpha=0.2, linewidth=0)
        for y, label in panel.references:
            ax.axhline(y, linestyle="--", color="grey", linewidth=1)
            ax.annotate(label, (1.0, y), xycoords=("axes fraction", "data"), ha="right", va="bottom",
                        fontsize=8, color="grey")
        ax.set_title(panel.title)
        ax.set_xlabel(panel.xlabel)
        ax.set_ylabel(panel.ylabel)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    tmp = Path(path).with_name(f".{Path(path).name}.tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
