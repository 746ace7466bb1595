"""Every experiment's presets against the paper's rules: seeds, the buffer-switch unit, and the
reasons `remidi list` gives for each deviation of a CPU-sized preset."""

import pytest

from remidi.cli import main
from remidi.experiments import all_experiments
from remidi.experiments.base import resolve_config

EXPERIMENTS = all_experiments()
UED = [name for name in EXPERIMENTS if not name.startswith("tabular")]


def test_the_maze_and_brax_experiments_have_a_cpu_preset():
    assert {"tmaze", "blindfold", "brax-ant", "brax-hopper"} <= {n for n in EXPERIMENTS if "cpu" in EXPERIMENTS[n].presets}


@pytest.mark.parametrize("name", list(EXPERIMENTS))
def test_paper_presets_default_to_the_papers_seeds(name):
    """Paper: 10 seeds for the lever, maze and Brax experiments, 50 for the tabular games."""
    want = 50 if name.startswith("tabular") else 10
    assert EXPERIMENTS[name].preset_seeds["paper"] == want


@pytest.mark.parametrize("name", UED)
def test_every_preset_switches_buffers_after_updates(name):
    """One buffer-switch unit for every experiment: train steps (the paper's 'every N iterations',
    as its authors' code counts), never replays."""
    exp = EXPERIMENTS[name]
    for preset in exp.presets:
        assert resolve_config(exp, preset, {}).remidi.count == "updates", (name, preset)


@pytest.mark.parametrize("name", [name for name in EXPERIMENTS if "cpu" in EXPERIMENTS[name].presets])
def test_cpu_preset_lists_each_deviation_from_paper_with_its_reason(name, capsys):
    exp = EXPERIMENTS[name]
    paper, cpu = resolve_config(exp, "paper", {}), resolve_config(exp, "cpu", {})
    assert main(["list", name]) == 0
    out = capsys.readouterr().out
    assert "cpu: deviates from paper in" in out
    from remidi.experiments.config import field_names, get_value

    differing = {key for key in field_names(paper) if get_value(paper, key) != get_value(cpu, key)}
    assert differing == set(exp.preset_reasons["cpu"])  # every deviation has a reason, and only those
    for key in differing:
        line = next(line for line in out.splitlines() if line.strip().startswith(key + " "))
        assert exp.preset_reasons["cpu"][key] in line
