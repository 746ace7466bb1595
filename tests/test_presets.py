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


@pytest.mark.parametrize("name", [name for name in EXPERIMENTS if "paper" in EXPERIMENTS[name].presets])
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


@pytest.mark.parametrize("name", [name for name in EXPERIMENTS if {"cpu", "paper"} <= set(EXPERIMENTS[name].presets)])
def test_cpu_preset_lists_each_deviation_from_paper_with_its_reason(name, capsys):
    exp = EXPERIMENTS[name]
    paper, cpu = resolve_config(exp, "paper", {}), resolve_config(exp, "cpu", {})
    assert main(["list", name]) == 0
    out = capsys.readouterr().out
    assert "cpu: deviates from paper in" in out
    from remidi.experiments.overrides import field_names, get_value

    differing = {key for key in field_names(paper) if get_value(paper, key) != get_value(cpu, key)}
    assert differing == set(exp.preset_reasons["cpu"])  # every deviation has a reason, and only those
    for key in differing:
        line = next(line for line in out.splitlines() if line.strip().startswith(key + " "))
        assert exp.preset_reasons["cpu"][key] in line


@pytest.mark.parametrize("text, value", [
    ("1000000000000000000000000000000", 10**30), ("1e30", 10**30), (10**30, 10**30), ("3.0", 3), (3.0, 3),
    (" 7 ", 7), ("-2", -2)])
def test_integers_stay_exact_integers(text, value):
    from remidi.engine.config import UEDConfig
    from remidi.experiments.overrides import apply_overrides

    got = apply_overrides(UEDConfig(), {"num_updates": text}).num_updates
    assert type(got) is int and got == value


@pytest.mark.parametrize("text", ["1.5", "nan", "inf", "abc", "", "1e-30", "1e99999999999", True])
def test_a_non_integer_is_refused_in_one_line(text):
    from remidi.errors import ConfigError
    from remidi.engine.config import UEDConfig
    from remidi.experiments.overrides import apply_overrides

    with pytest.raises(ConfigError, match=r"^num_updates: expected an integer"):
        apply_overrides(UEDConfig(), {"num_updates": text})
