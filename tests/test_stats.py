"""remidi.stats and `remidi compare`: hand computations on fixed numbers, brute-force enumerations,
and (where it is installed) rliable's own functions as an independent check."""

import itertools
import json
import math

import numpy as np
import pytest
import scipy.stats

from remidi import stats
from remidi.cli import main
from remidi.runs.compare import compare

# ------------------------------------------------------------------------------ remidi.stats


def test_mean_and_sample_std_use_ddof_1():
    mean, std = stats.mean_and_sample_std([1.0, 2.0, 3.0, 4.0])
    assert mean == 2.5 and std == pytest.approx(math.sqrt((2.25 + 0.25 + 0.25 + 2.25) / 3))  # not / 4
    mean, std = stats.mean_and_sample_std([0.0, 0.13])
    assert std == pytest.approx(0.13 / math.sqrt(2))  # the "0.065 ± 0.065" was ddof 0
    mean, std = stats.mean_and_sample_std([3.0])
    assert mean == 3.0 and math.isnan(std)
    assert all(math.isnan(v) for v in stats.mean_and_sample_std([]))
    assert math.isnan(stats.mean_and_sample_std([1.0, None])[0])  # a seed without a value: undefined


def test_iqm_is_the_mean_of_the_middle_half():
    assert stats.iqm([8, 1, 7, 2, 6, 3, 5, 4]) == 4.5  # mean of 3, 4, 5, 6
    assert stats.iqm([0, 1, 2, 3, 4, 5, 6, 7, 8, 100]) == pytest.approx(4.5)  # 10 seeds: middle 6 (2..7)
    assert stats.iqm([0.0, 0.1, 0.3, 1.0]) == pytest.approx(0.2)  # 4 seeds: middle 2
    assert stats.iqm([5.0, 9.0]) == 7.0  # fewer than 4: nothing cut


def test_bootstrap_ci_of_two_values_is_exactly_their_range():
    # resampled means of (a, b) are a, (a+b)/2, b with probabilities 1/4, 1/2, 1/4: the 2.5% and
    # 97.5% percentiles are a and b
    assert stats.bootstrap_ci([1.0, 2.0]) == (1.0, 2.0)


def test_bootstrap_ci_contains_the_mean_and_shrinks_with_more_data():
    rng = np.random.default_rng(1)
    small, large = rng.normal(0.0, 1.0, 5), rng.normal(0.0, 1.0, 80)
    (lo_s, hi_s), (lo_l, hi_l) = stats.bootstrap_ci(small), stats.bootstrap_ci(large)
    assert lo_s < small.mean() < hi_s and lo_l < large.mean() < hi_l
    assert hi_l - lo_l < 0.5 * (hi_s - lo_s)
    # about 2 × 1.96 / sqrt(80) = 0.44 wide for 80 standard normal values
    assert 0.3 < hi_l - lo_l < 0.6
    assert stats.bootstrap_ci(small) == (lo_s, hi_s)  # deterministic for a given seed
    lo, hi = stats.bootstrap_ci(small, confidence=0.5)
    assert lo_s < lo < hi < hi_s


def test_bootstrap_ci_of_the_iqm_and_bca():
    values = [0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9]
    lo, hi = stats.bootstrap_ci(values, stats.iqm)
    assert lo < stats.iqm(values) < hi and 0.0 <= lo and hi <= 0.9
    lo_b, hi_b = stats.bootstrap_ci(values, method="BCa")
    assert lo_b < 0.45 < hi_b


def test_degenerate_samples():
    assert stats.bootstrap_ci([0.3] * 5) == (0.3, 0.3)  # every resample is the sample
    assert stats.bootstrap_ci([0.0] * 4, method="BCa") == (0.0, 0.0)  # where SciPy's BCa fails
    assert all(math.isnan(v) for v in stats.bootstrap_ci([0.3]))  # one seed: no interval
    assert all(math.isnan(v) for v in stats.bootstrap_ci([0.3, math.nan, 0.1]))
    assert stats.probability_of_improvement([1.0, 1.0], [1.0, 1.0]) == (0.5, 0.5, 0.5)
    assert stats.probability_of_improvement([2.0, 3.0], [0.0, 1.0]) == (1.0, 1.0, 1.0)  # separated: every resample too


def test_stratified_bootstrap_resamples_within_each_stratum():
    values = [0.0, 1.0, 2.0, 3.0, 100.0, 101.0, 102.0, 103.0]
    strata = ["a"] * 4 + ["b"] * 4
    lo, hi = stats.bootstrap_ci(values, strata=strata)
    # four of each stratum in every resample: the pooled mean stays within 51.5 ± 1.5
    assert 50.0 <= lo < 51.5 < hi <= 53.0
    lo_u, hi_u = stats.bootstrap_ci(values)  # unstratified: the mix of strata varies
    assert hi_u - lo_u > 10 * (hi - lo)
    with pytest.raises(ValueError, match="strata: 3 labels for 8 values"):
        stats.bootstrap_ci(values, strata=["a", "b", "c"])
    assert all(math.isnan(v) for v in stats.bootstrap_ci([0.0, 1.0, 5.0], strata=["a", "a", "b"]))


def test_probability_of_improvement_by_hand():
    # x=1 beats 0, 0 and ties 1: 2.5; x=2, 3, 4 each beat 0, 0, 1: 3 each; 5 beats none → 11.5 / 16
    est = stats.probability_of_improvement([1, 2, 3, 4], [0, 0, 1, 5])
    assert est.value == 11.5 / 16
    u = scipy.stats.mannwhitneyu([1, 2, 3, 4], [0, 0, 1, 5]).statistic  # the Mann–Whitney U / (n·m)
    assert est.value == u / 16
    assert 0.0 <= est.low < est.value < est.high <= 1.0
    assert stats.probability_of_improvement([0, 0, 1, 5], [1, 2, 3, 4]).value == 1 - 11.5 / 16
    one = stats.probability_of_improvement([1.0], [0.0, 2.0])
    assert one.value == 0.5 and math.isnan(one.low) and math.isnan(one.high)  # one seed: no interval


def test_probability_of_improvement_averages_over_strata():
    x, y = [1, 2, 3, 4, 1, 2], [0, 0, 1, 5, 0, 3]
    est = stats.probability_of_improvement(x, y, x_strata=list("aaaabb"), y_strata=list("aaaabb"))
    # a: 11.5/16 as above; b: (1, 2) against (0, 3): 1 > 0, 2 > 0 → 2 of 4 = 0.5; average 0.609375
    assert est.value == (11.5 / 16 + 0.5) / 2
    assert est.low < est.value < est.high
    with pytest.raises(ValueError, match="same strata"):
        stats.probability_of_improvement(x, y, x_strata=list("aaaabb"), y_strata=list("aaaacc"))


def _brute_force_pvalue(x, y, paired):
    """P(statistic ≥ observed) over every arrangement, enumerated here without SciPy."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    observed = x.mean() - y.mean()
    if paired:
        d = x - y
        null = [np.mean(np.array(signs) * d) for signs in itertools.product((1, -1), repeat=len(d))]
    else:
        pooled = np.concatenate([x, y])
        null = []
        for idx in itertools.combinations(range(len(pooled)), len(x)):
            mask = np.zeros(len(pooled), bool)
            mask[list(idx)] = True
            null.append(pooled[mask].mean() - pooled[~mask].mean())
    return np.mean(np.array(null) >= observed - 1e-12)


def test_permutation_pvalue_by_hand():
    # 3 against 3, fully separated: 1 of the C(6, 3) = 20 relabellings is as extreme
    assert stats.permutation_pvalue([4, 5, 6], [1, 2, 3]) == pytest.approx(1 / 20)
    assert stats.permutation_pvalue([1, 2, 3], [4, 5, 6]) == pytest.approx(1.0)
    # paired, four differences all positive (and distinct): 1 of 2^4 = 16 sign flips
    assert stats.permutation_pvalue([2, 4, 6, 8], [1, 2, 3, 4], paired=True) == pytest.approx(1 / 16)
    # x = (3, 5), y = (1, 4): difference 1.5; of the 6 choices of x from (1, 3, 4, 5) only {4, 5} (2.5)
    # and {3, 5} (1.5) reach it → 2/6
    assert stats.permutation_pvalue([3, 5], [1, 4]) == pytest.approx(1 / 3)
    # paired differences (3, 1, −1), sum 3: of the 8 sign flips +3+1+1, +3+1−1, +3−1+1 reach it → 3/8
    assert stats.permutation_pvalue([3, 1, 0], [0, 0, 1], paired=True) == pytest.approx(3 / 8)
    assert stats.permutation_pvalue([1, 2], [0, 0, 1], alternative="less") == pytest.approx(1.0)


def test_permutation_pvalue_matches_a_brute_force_enumeration():
    x = [0.29, 0.42, 0.09, 0.14, 0.31]  # with a tie across groups
    y = [0.27, 0.20, 0.03, 0.09, 0.10]
    for paired in (False, True):
        assert stats.permutation_pvalue(x, y, paired=paired) == pytest.approx(_brute_force_pvalue(x, y, paired))


def test_the_exact_independent_pvalue_equals_scipys_enumeration():
    # our vectorised enumeration of the relabellings against scipy.stats.permutation_test's own,
    # on continuous values and on tied solve rates (ties across groups and at the observed value)
    rng = np.random.default_rng(1)
    for trial in range(24):
        n, m = rng.integers(2, 8, 2)
        x, y = (rng.integers(0, 4, n) / 10, rng.integers(0, 4, m) / 10) if trial % 2 else (rng.normal(size=n), rng.normal(size=m))
        for alternative in ("greater", "less", "two-sided"):
            ref = scipy.stats.permutation_test((x, y), stats._mean_difference, vectorized=True, alternative=alternative,
                                               permutation_type="independent", n_resamples=np.inf).pvalue
            assert stats.permutation_pvalue(x, y, alternative=alternative) == float(ref), (x, y, alternative)


def test_permutation_pvalue_is_exact_for_ten_seeds_and_sampled_beyond():
    x, y = np.arange(10.0) + 3, np.arange(10.0)
    assert stats.permutation_count(10, 10, paired=False) == 184_756 <= stats.MAX_EXACT
    assert stats.permutation_count(10, 10, paired=True) == 1024
    exact = stats.permutation_pvalue(x, y)
    assert exact * 184_756 == pytest.approx(round(exact * 184_756))  # a count of arrangements
    sampled = stats.permutation_pvalue(x, y, max_exact=1000, n_resamples=20_000)
    assert sampled == pytest.approx(exact, abs=0.005) and sampled != exact
    with pytest.raises(ValueError, match="pairs need the same seeds"):
        stats.permutation_pvalue([1, 2, 3], [1, 2], paired=True)
    assert math.isnan(stats.permutation_pvalue([1, math.nan], [0, 0]))


def test_holm_by_hand():
    # sorted 0.01, 0.03, 0.04 → × 3, 2, 1 = 0.03, 0.06, 0.04 → running maximum 0.03, 0.06, 0.06
    assert stats.holm([0.01, 0.04, 0.03]).tolist() == pytest.approx([0.03, 0.06, 0.06])
    assert stats.holm([0.5, 0.9]).tolist() == [1.0, 1.0]  # capped at 1
    assert stats.holm([0.02]).tolist() == [0.02]  # one comparison: unchanged
    adjusted = stats.holm([0.01, math.nan, 0.04])  # a comparison not made does not count
    assert adjusted[0] == pytest.approx(0.02) and math.isnan(adjusted[1]) and adjusted[2] == pytest.approx(0.04)


def test_holm_agrees_with_statsmodels():
    multitest = pytest.importorskip("statsmodels.stats.multitest")
    p = np.random.default_rng(0).uniform(0, 0.2, 7)
    assert stats.holm(p) == pytest.approx(multitest.multipletests(p, method="holm")[1])


def test_iqm_and_probability_of_improvement_agree_with_rliable():
    # rliable 1.2's metrics module; its `library` (bootstrap) module does not import with pandas 3
    # (arch 7.2: "deprecate_kwarg() missing 1 required positional argument"), so intervals are not compared
    metrics = pytest.importorskip("rliable.metrics")
    rng = np.random.default_rng(3)
    for n, m in ((4, 4), (10, 10), (7, 5)):
        x, y = rng.integers(0, 5, n) / 4, rng.integers(0, 5, m) / 4  # ties, as solve rates have
        assert stats.iqm(x) == pytest.approx(metrics.aggregate_iqm(x[:, None]))
        assert stats.probability_of_improvement(x, y).value == pytest.approx(
            metrics.probability_of_improvement(x[:, None], y[:, None]))
    # several tasks: rliable averages the per-task values, as x_strata / y_strata do
    x, y = rng.normal(size=(6, 3)), rng.normal(size=(6, 3))
    ours = stats.probability_of_improvement(x.T.ravel(), y.T.ravel(), x_strata=np.repeat([0, 1, 2], 6),
                                            y_strata=np.repeat([0, 1, 2], 6))
    assert ours.value == pytest.approx(metrics.probability_of_improvement(x, y))


# ------------------------------------------------------------------------------ remidi compare


def write_run(folder, experiment, algo, per_seed, seeds=None, metric="solve_rate/mean"):
    """A finished run's summary.json, as table._read_summary expects it."""
    folder.mkdir(parents=True)
    seeds = list(range(len(per_seed))) if seeds is None else seeds
    doc = {"experiment": experiment, "algo": algo, "preset": "cpu", "seeds": seeds,
           "metrics": {metric: {"mean": float(np.mean(per_seed)), "std": float(np.std(per_seed)),
                                "per_seed": per_seed}}}
    (folder / "summary.json").write_text(json.dumps(doc))


def test_compare_function_by_hand():
    result = compare({"tmaze": {0: 1.0, 1: 2.0, 2: 3.0, 3: 4.0}}, {"tmaze": {0: 0.0, 1: 0.0, 2: 1.0, 3: 5.0}})
    r = result["experiments"]["tmaze"]
    assert r["algo"]["mean"] == 2.5 and r["baseline"]["mean"] == 1.5 and r["difference"] == 1.0
    assert r["algo"]["std"] == pytest.approx(math.sqrt(5 / 3)) and r["algo"]["iqm"] == 2.5
    assert r["probability_of_improvement"] == 11.5 / 16 == result["probability_of_improvement"]
    assert r["poi_ci"] == result["poi_ci"]  # one experiment: the average is that experiment
    assert r["p_value"] == pytest.approx(_brute_force_pvalue([1, 2, 3, 4], [0, 0, 1, 5], False))
    assert r["exact"] and r["p_holm"] == r["p_value"] and not result["paired"]
    paired = compare({"t": {0: 1.0, 1: 2.0, 2: 3.0, 3: 4.0}}, {"t": {3: 3.5, 2: 2.5, 1: 1.5, 0: 0.5}}, paired=True)
    assert paired["experiments"]["t"]["p_value"] == pytest.approx(1 / 16)  # pairs matched by seed, not order
    json.dumps(result)  # JSON-ready


def test_compare_prints_the_numbers(tmp_path, capsys):
    write_run(tmp_path / "run" / "remidi", "tmaze", "remidi", [0.4, 0.5, 0.6])
    write_run(tmp_path / "run" / "plr", "tmaze", "plr", [0.1, 0.2, 0.3])
    assert main(["compare", str(tmp_path / "run"), "--metric", "solve_rate/mean", "--algo", "remidi",
                 "--baseline", "plr"]) == 0
    out = capsys.readouterr().out
    assert "remidi   3 seeds  mean 0.50 ± 0.10" in out and "plr      3 seeds  mean 0.20 ± 0.10" in out
    assert "difference of means   0.30" in out
    assert "P(remidi > plr)  1.00  95% CI [1.00, 1.00]" in out
    assert "permutation p-value   0.05 (exact, one-sided, independent groups)" in out  # 1/20
    assert "Holm" not in out and "ddof 1" in out


def test_compare_paired_several_experiments_and_plot(tmp_path, capsys):
    write_run(tmp_path / "a" / "remidi", "tmaze", "remidi", [2.0, 4.0, 6.0, 8.0])
    write_run(tmp_path / "a" / "plr", "tmaze", "plr", [1.0, 2.0, 3.0, 4.0])
    write_run(tmp_path / "b" / "remidi", "blindfold", "remidi", [0.1, 0.3, 0.2, 0.2])
    write_run(tmp_path / "b" / "plr", "blindfold", "plr", [0.2, 0.1, 0.0, 0.0])
    fig = tmp_path / "fig.png"
    assert main(["compare", str(tmp_path / "a"), str(tmp_path / "b"), "--metric", "solve_rate/mean",
                 "--algo", "remidi", "--baseline", "plr", "--paired", "--out", str(fig)]) == 0
    out = capsys.readouterr().out
    # tmaze: 4 positive pairs → 1/16; blindfold: differences (−0.1, 0.2, 0.2, 0.2), sum 0.5: of the 16
    # sign flips, those reaching 0.5 keep the three +0.2 and either sign of 0.1 → 2/16; Holm: 2 × 1/16, 1/8
    assert "0.0625 (exact, one-sided, paired by seed); Holm over 2 experiments: 0.125" in out
    assert "0.125 (exact, one-sided, paired by seed); Holm over 2 experiments: 0.125" in out
    # average of the per-experiment probabilities: tmaze (2,4,6,8) vs (1,2,3,4): 2>1; 4>1,2,3; 6>all; 8>all;
    # ties 2=2, 4=4 → (1 + 0.5 + 3 + 0.5 + 4 + 4) / 16 = 13/16; blindfold: 0.1 vs (0.2,0.1,0,0) = 2.5;
    # 0.3 → 4; 0.2 → 3.5 twice → 13.5/16; average (13 + 13.5) / 32 = 0.828 → 0.83
    assert "average over 2 experiments: P(remidi > plr)  0.83" in out
    assert fig.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_compare_merges_runs_of_the_same_experiment(tmp_path, capsys):
    write_run(tmp_path / "r1", "tmaze", "remidi", [0.4, 0.5], seeds=[0, 1])
    write_run(tmp_path / "r2", "tmaze", "remidi", [0.6], seeds=[2])
    write_run(tmp_path / "p", "tmaze", "plr", [0.1, 0.2, 0.3])
    args = ["compare", str(tmp_path / "r1"), str(tmp_path / "r2"), str(tmp_path / "p"), "--metric",
            "solve_rate/mean", "--algo", "remidi", "--baseline", "plr"]
    assert main(args) == 0
    assert "remidi   3 seeds  mean 0.50 ± 0.10" in capsys.readouterr().out
    write_run(tmp_path / "r3", "tmaze", "remidi", [0.7], seeds=[1])
    assert main(args[:4] + [str(tmp_path / "r3")] + args[4:]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "RUN: seed 1 of tmaze / remidi is in two runs" in err


def test_compare_last_k_reads_metrics_csv(tmp_path, capsys):
    for algo, rows in (("remidi", [(0, [0.0, 0.6]), (1, [0.0, 0.8])]), ("plr", [(0, [0.9, 0.1]), (1, [0.9, 0.3])])):
        write_run(tmp_path / algo, "tmaze", algo, [0.0, 0.0])
        lines = ["seed,step,metric,value"] + [f"{s},{10 * (t + 1)},solve_rate/mean,{v}"
                                              for s, values in rows for t, v in enumerate(values)]
        (tmp_path / algo / "metrics.csv").write_text("\n".join(lines) + "\n")
    assert main(["compare", str(tmp_path / "remidi"), str(tmp_path / "plr"), "--metric", "solve_rate/mean",
                 "--algo", "remidi", "--baseline", "plr", "--last", "1"]) == 0
    out = capsys.readouterr().out
    assert "mean 0.70 ± 0.14" in out and "mean 0.20 ± 0.14" in out


@pytest.mark.parametrize("extra, needle", [
    (["--metric", "nosuch", "--algo", "remidi", "--baseline", "plr"],
     "--metric: no run has 'nosuch'; allowed: solve_rate/mean"),
    (["--metric", "solve_rate/mean", "--algo", "remid", "--baseline", "plr"],
     "--algo: no run of 'remid'; allowed: remidi, plr"),
    (["--metric", "solve_rate/mean", "--algo", "remidi", "--baseline", "remidi"],
     "--baseline: 'remidi' is also --algo"),
    (["--metric", "solve_rate/mean", "--algo", "remidi", "--baseline", "plr", "--paired"],
     "--paired: on tmaze the algorithm has seeds [0, 1, 2] and the baseline [0, 1, 5]"),
    (["--metric", "solve_rate/mean", "--algo", "remidi", "--baseline", "plr", "--out", "fig.pdf"],
     "--out: must be a .png file"),
    (["--metric", "solve_rate/mean", "--algo", "remidi", "--baseline", "plr", "--last", "0"],
     "--last: must be an integer ≥ 1"),
    (["--algo", "remidi", "--baseline", "plr"], "the following arguments are required: --metric"),
])
def test_compare_bad_input_is_one_line_exit_2(tmp_path, capsys, extra, needle):
    write_run(tmp_path / "remidi", "tmaze", "remidi", [0.4, 0.5, 0.6])
    write_run(tmp_path / "plr", "tmaze", "plr", [0.1, 0.2, 0.3], seeds=[0, 1, 5])
    assert main(["compare", str(tmp_path / "remidi"), str(tmp_path / "plr"), *extra]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("remidi: error: ") and needle in err, err


def test_compare_needs_both_algorithms_on_every_experiment(tmp_path, capsys):
    write_run(tmp_path / "remidi", "tmaze", "remidi", [0.4, 0.5])
    write_run(tmp_path / "plr", "tmaze", "plr", [0.1, 0.2])
    write_run(tmp_path / "plr-b", "blindfold", "plr", [0.1, 0.2])
    assert main(["compare", *(str(tmp_path / n) for n in ("remidi", "plr", "plr-b")), "--metric",
                 "solve_rate/mean", "--algo", "remidi", "--baseline", "plr"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no run of remidi with solve_rate/mean on blindfold" in err


def test_help_of_table_and_compare(capsys):
    for sub in ([], ["table"], ["compare"]):  # help strings are %-formatted: a bare "95%" would crash here
        with pytest.raises(SystemExit) as exc:
            main([*sub, "--help"])
        assert exc.value.code == 0
        out = capsys.readouterr().out
        assert "usage: remidi" in out and "95%" in out
