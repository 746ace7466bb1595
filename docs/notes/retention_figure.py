"""Per-variant mean ± std over seeds of the darkroom measurement runs, before/after the switch; the figure."""
import csv, collections, sys, json
from pathlib import Path
import numpy as np

ROOT = Path("/work/h4runs")
VARIANTS = [("plr", "plr", "PLR⊥"), ("masked", "remidi", "ReMiDi masked (default)"), ("combine", "remidi", "ReMiDi combine"),
            ("reh01", "remidi", "ReMiDi rehearsal 0.1"), ("reh03", "remidi", "ReMiDi rehearsal 0.3")]
VARIANTS += [tuple(v.split(":")) for v in sys.argv[1:]]
METRICS = ["solve_rate/lit", "solve_rate/dark", "buffer_solve_rate/b0", "buffer_solve_rate/b1", "buffer_fraction/dark/b0",
           "buffer_fraction/dark/b1", "replay_fraction/dark"]

def load(run, algo):
    f = ROOT / run / algo / "metrics.csv"
    if not f.exists():
        f = ROOT / run / "metrics.csv"
    if not f.exists():
        return None
    d = collections.defaultdict(dict)
    for r in csv.DictReader(open(f)):
        d[r["metric"]][(int(r["seed"]), int(r["step"]))] = float(r["value"])
    return d

def series(d, metric):
    """steps i[T], values f[S, T]."""
    if metric not in d:
        return None, None
    seeds = sorted({s for s, _ in d[metric]}); steps = sorted({t for _, t in d[metric]})
    return np.array(steps), np.array([[d[metric].get((s, t), np.nan) for t in steps] for s in seeds])

out = {}
for run, algo, label in VARIANTS:
    d = load(run, algo)
    if d is None:
        print(f"{label}: not yet"); continue
    row = {}
    for m in METRICS:
        steps, v = series(d, m)
        if steps is None:
            continue
        for at in sorted({300, 350, 400, int(steps.max())}):
            if at in steps:
                x = v[:, list(steps).index(at)]
                row[f"{m}@{at}"] = (float(np.nanmean(x)), float(np.nanstd(x)), len(x))
    out[label] = row
    print(f"== {label} ({run})")
    for k, (mu, sd, n) in row.items():
        print(f"   {k:32s} {mu:.3f} ± {sd:.3f} (n={n})")
json.dump(out, open(ROOT / "summary_table.json", "w"), indent=1)

if "--plot" in sys.argv or True:
    import matplotlib; matplotlib.use("Agg"); import matplotlib.pyplot as plt
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for (run, algo, label), color in zip(VARIANTS, plt.cm.tab10.colors):
        d = load(run, algo)
        if d is None: continue
        for ax, m in zip(axes, ["buffer_solve_rate/b0", "solve_rate/lit", "solve_rate/dark"]):
            steps, v = series(d, m)
            if steps is None: continue
            mu, sd = np.nanmean(v, 0), np.nanstd(v, 0)
            ax.plot(steps, mu, label=label, color=color); ax.fill_between(steps, mu - sd, mu + sd, color=color, alpha=0.15)
    for ax, t in zip(axes, ["solve rate on buffer 1's levels", "solve rate, lit levels", "solve rate, dark levels (chance 1/12)"]):
        ax.axvline(300, color="grey", ls="--", lw=1); ax.set_title(t); ax.set_xlabel("update")
    axes[1].legend(fontsize=7); axes[2].axhline(1/12, color="black", ls=":", lw=1)
    fig.suptitle("darkroom (5×5, 12 goals), cpu preset, 3 seeds (mean ± std); dashed: ReMiDi's buffer switch")
    fig.tight_layout(); fig.savefig(ROOT / "retention.png", dpi=90)
