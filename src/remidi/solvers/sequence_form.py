"""Exact minimax regret and BLP for finite multi-step games, via the sequence form.

Each level is a tree of chance nodes, agent decision nodes labelled with an observation, and
terminal rewards. The agent knows only its action-observation history (AOH)
``(o0, a0, o1, a1, ..., ok)``: decision nodes with the same AOH, in any levels, form one
information set and must offer the same actions. Because the AOH contains the whole past, the
agent has perfect recall, so realisation plans (:mod:`remidi.solvers.lp`) represent exactly the
behavioural policies, and the regret games are linear programs.

Policies are mappings ``{AOH tuple: {action: probability}}``. Solver results list only the
information sets the policy itself reaches (``x[parent] > tol``); elsewhere any behaviour is
equivalent because the agent never arrives there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping, Union

import numpy as np

from remidi.solvers import checks, lp, polytope
from remidi.solvers.onestep import OneStepGame, solve_mmr as solve_onestep_mmr
from remidi.solvers.results import BLPResult, MMRResult, Round

AOH = tuple[str, ...]
TreePolicy = dict[AOH, dict[str, float]]


@dataclass(frozen=True)
class Terminal:
    """A leaf paying ``reward``."""

    reward: float


@dataclass(frozen=True)
class Chance:
    """A chance node: ``outcomes`` is a tuple of (probability, child node)."""

    outcomes: tuple[tuple[float, "Node"], ...]


@dataclass(frozen=True)
class Decision:
    """An agent decision node showing ``observation``; ``children`` maps action name -> node."""

    observation: str
    children: Mapping[str, "Node"]


Node = Union[Terminal, Chance, Decision]


@dataclass(frozen=True)
class TreeGame:
    """actions [A] names; level_names [L]; trees [L] root nodes."""

    actions: tuple[str, ...]
    level_names: tuple[str, ...]
    trees: tuple[Node, ...]


@dataclass(frozen=True)
class SequenceForm:
    """Compiled game.

    infosets [I]: AOH of each information set (parents first); infoset_actions [I]: action names
    available there, in ``game.actions`` order; poly: the plan polytope; payoff [L, S] (of the
    rewards less ``centre``); reach [L, I]: chance probability of each information set per level;
    members [I]: the (level index, chance probability, decision node) triples making up each
    information set; centre [L]: the amount subtracted from every reward of each level (zeros
    unless built ``centred``).
    """

    infosets: tuple[AOH, ...]
    infoset_actions: tuple[tuple[str, ...], ...]
    poly: polytope.Polytope
    payoff: np.ndarray
    reach: np.ndarray
    members: tuple[tuple[tuple[int, float, Decision], ...], ...]
    centre: np.ndarray


def _describe(aoh: AOH) -> str:
    """An AOH as text, e.g. ``s0 a1 sA``."""
    return " ".join(aoh)


def build_sequence_form(game: TreeGame, centred: bool = False) -> SequenceForm:
    """Compile a tree game; raises ValueError if an information set has inconsistent actions.

    ``centred``: subtract from each level's rewards the midpoint of its smallest and largest
    reward, which leaves every regret unchanged and keeps a level whose rewards are all near
    1e12 from dwarfing the others in the LPs. A shift is exact only if the level's terminal
    probability is 1 under every plan, so a level whose chance probabilities miss 1 by more
    than a few roundings is left as it is.
    """
    index: dict[AOH, int] = {}
    infosets: list[AOH] = []
    actions: list[tuple[str, ...]] = []
    parents: list[int] = []
    children: list[tuple[int, ...]] = []
    members: list[list[tuple[int, float, Decision]]] = []
    payoff_terms: list[tuple[int, int, float, float]] = []
    counter = [1]
    owner: dict[AOH, str] = {}

    def visit(level: int, node: Node, aoh: AOH, seq: int, prob: float) -> None:
        if isinstance(node, Terminal):
            payoff_terms.append((level, seq, prob, node.reward))
        elif isinstance(node, Chance):
            for p, child in node.outcomes:
                visit(level, child, aoh, seq, prob * p)
        else:
            key = aoh + (node.observation,)
            here = tuple(a for a in game.actions if a in node.children)
            if key not in index:
                index[key] = len(infosets)
                infosets.append(key)
                actions.append(here)
                parents.append(seq)
                children.append(tuple(range(counter[0], counter[0] + len(here))))
                members.append([])
                counter[0] += len(here)
                owner[key] = game.level_names[level]
            info = index[key]
            if actions[info] != here:
                raise ValueError(
                    f"information set '{_describe(key)}': actions {list(here)} in level "
                    f"'{game.level_names[level]}' but {list(actions[info])} in level '{owner[key]}'"
                )
            members[info].append((level, prob, node))
            for a, s in zip(here, children[info]):
                visit(level, node.children[a], key + (a,), s, prob)

    for level, tree in enumerate(game.trees):
        visit(level, tree, (), 0, 1.0)
    poly = polytope.Polytope(counter[0], tuple(parents), tuple(children))
    centre = _centres(poly, len(game.trees), payoff_terms) if centred else np.zeros(len(game.trees))
    payoff = np.zeros((len(game.trees), poly.n_sequences))
    with np.errstate(invalid="ignore"):  # a non-finite reward stays non-finite; the solvers refuse it
        for level, seq, prob, reward in payoff_terms:
            payoff[level, seq] += prob * (reward - centre[level])
    reach = np.zeros((len(game.trees), len(infosets)))
    for info, group in enumerate(members):
        for level, prob, _ in group:
            reach[level, info] += prob
    return SequenceForm(tuple(infosets), tuple(actions), poly, payoff, reach,
                        tuple(tuple(m) for m in members), centre)


def _centres(poly: polytope.Polytope, n_levels: int, terms: list[tuple[int, int, float, float]]) -> np.ndarray:
    """Per level [L], the midpoint of its terminal rewards, or 0 where the terminal probability
    (from ``terms``: level, sequence, chance probability, reward) is not 1 under every plan."""
    low, high = np.full(n_levels, np.inf), np.full(n_levels, -np.inf)
    mass = np.zeros((n_levels, poly.n_sequences))
    for level, seq, prob, reward in terms:
        if prob > 0:
            low[level], high[level] = min(low[level], reward), max(high[level], reward)
        mass[level, seq] += prob
    most, least = lp.best_response_values(poly, mass), -lp.best_response_values(poly, -mass)
    exact = np.maximum(np.abs(most - 1.0), np.abs(least - 1.0)) <= 4 * np.finfo(float).eps
    return np.where(exact & np.isfinite(low), low / 2 + high / 2, 0.0)


def _policy(form: SequenceForm, plan: np.ndarray, tol: float) -> TreePolicy:
    """Behavioural policy at the information sets the plan [S] reaches (``x[parent] > tol``)."""
    return {
        aoh: dict(zip(form.infoset_actions[i], map(float, form.poly.behaviour(plan, i))))
        for i, aoh in enumerate(form.infosets)
        if plan[form.poly.parent[i]] > tol
    }


def node_value(node: Node, aoh: AOH, policy: Mapping[AOH, Mapping[str, float]]) -> float:
    """Expected return of a subtree whose decision nodes follow ``policy``; ``aoh`` is the history
    before ``node``. Zero-probability branches are skipped, so only reached AOHs need entries."""
    if isinstance(node, Terminal):
        return node.reward
    if isinstance(node, Chance):
        return sum(p * node_value(child, aoh, policy) for p, child in node.outcomes if p > 0)
    key = aoh + (node.observation,)
    if key not in policy:
        raise ValueError(f"policy has no entry for reached history '{_describe(key)}'")
    return sum(
        p * node_value(node.children[a], key + (a,), policy)
        for a, p in policy[key].items() if p > 0
    )


def optimal_returns(game: TreeGame) -> np.ndarray:
    """Best return U* [L] on each level alone."""
    form = build_sequence_form(game)
    return lp.best_response_values(form.poly, form.payoff)


def policy_return(game: TreeGame, policy: Mapping[AOH, Mapping[str, float]]) -> np.ndarray:
    """Expected return [L] of a behavioural policy on each level."""
    return np.array([node_value(tree, (), policy) for tree in game.trees])


def policy_regret(game: TreeGame, policy: Mapping[AOH, Mapping[str, float]]) -> np.ndarray:
    """Regret [L] of a behavioural policy on each level."""
    return optimal_returns(game) - policy_return(game, policy)


def _support_names(game: TreeGame, support: np.ndarray) -> tuple[str, ...]:
    """Names of the levels where support [L] is true."""
    return tuple(n for n, s in zip(game.level_names, support) if s)


class _Checker:
    """Checks the rounds of a centred sequence form as they are solved (:func:`checks.check_rounds`).

    Regrets, guarantees and bounds come from the regret gaps of the rewards
    (:func:`polytope.regret_gaps`), in the LPs' normalised units and then multiplied by their scale.
    """

    def __init__(self, game: TreeGame, form: SequenceForm):
        checks.require_finite(game.level_names, form.payoff)
        self.names, self.form = game.level_names, form
        optimal = lp.best_response_values(form.poly, form.payoff)
        self.scale = lp.normalise(form.payoff, optimal)
        payoff = form.payoff / self.scale
        self.gaps = polytope.regret_gaps(form.poly, payoff)
        with np.errstate(over="ignore"):
            self.spread = self.scale * (optimal / self.scale + lp.best_response_values(form.poly, -payoff))
        self.regrets: list[np.ndarray] = []
        self.bounds: list[float] = []
        self.guarantees: list[float] = []

    def regret(self, plan: np.ndarray) -> np.ndarray:
        """Regret [L] of a plan [S] (inf where it overflows)."""
        with np.errstate(over="ignore"):
            return self.scale * (self.gaps @ plan)

    def _claims(self, raws: list[lp.RawRound], first: int) -> checks.Claims:
        """Claims of ``raws[first:]`` (levels covered before them: round -1)."""
        n_rounds = len(raws) - first
        round_of = np.full(len(self.names), n_rounds)
        adversary = np.zeros(len(self.names))
        for k, raw in enumerate(raws):
            round_of[raw.support] = k - first if k >= first else -1
            adversary[raw.support] = raw.adversary[raw.support]
        return checks.Claims(np.array([r.value for r in raws[first:]]), np.array(self.bounds[first:]),
                         np.array(self.guarantees[first:]), round_of, adversary,
                         np.array(self.regrets[first:]), np.full(len(self.names), self.scale))

    def __call__(self, raws: list[lp.RawRound]) -> None:
        """Check the last of the rounds solved so far."""
        raw, prev = raws[-1], (raws[-2].plan if len(raws) > 1 else None)

        def least(adversary: np.ndarray) -> float:
            with np.errstate(over="ignore"):
                return self.scale * polytope.least_regret(self.form.poly, adversary @ self.gaps, raw.fixed, prev)

        self.regrets.append(self.regret(raw.plan))
        self.bounds.append(least(raw.certificate))
        self.guarantees.append(least(raw.adversary))
        checks.check_rounds(self._claims(raws, len(raws) - 1), self.names, self.spread, first=len(raws),
                        previous=raws[-2].value if len(raws) > 1 else None)

    def final(self, raws: list[lp.RawRound]) -> np.ndarray:
        """Check the final plan against every round; its regret [L]."""
        regret = self.regret(raws[-1].plan)
        checks.check_final(self._claims(raws, 0), regret, self.names, self.spread)
        return regret

    def optimal_return(self) -> np.ndarray:
        """Best return U* [L] on each level alone, in the rewards' own units."""
        return lp.best_response_values(self.form.poly, self.form.payoff) + self.form.centre


def solve_mmr(game: TreeGame, tol: float = 1e-7) -> MMRResult[TreePolicy]:
    """Minimax regret: value, behavioural policy, maximal-support adversary [L], regret [L].

    Solved on the centred rewards (:func:`build_sequence_form`) and checked
    (:func:`remidi.solvers.checks.check_rounds`).
    """
    form = build_sequence_form(game, centred=True)
    check = _Checker(game, form)
    raw = lp.solve_mmr_plan(form.poly, form.payoff, tol)
    check([raw])
    return MMRResult(raw.value, _policy(form, raw.plan, tol), raw.adversary, check.regrets[0],
                     check.optimal_return())


def solve_blp(game: TreeGame, tol: float = 1e-7, progress=None) -> BLPResult[TreePolicy]:
    """Bayesian level-perfect minimax regret by iterated refinement over AOHs.

    ``tol`` is the probability below which a level is outside an adversary's support and a
    sequence counts as never played. ``progress`` as in :func:`remidi.solvers.lp.solve_blp_plans`.

    Each round fixes the behaviour on every AOH realisable under the previous round's policy on
    a level of an earlier support (see :func:`remidi.solvers.lp.solve_blp_plans`). Rewards are
    centred per level (:func:`build_sequence_form`) and every round is checked as it is solved.
    """
    form = build_sequence_form(game, centred=True)
    check = _Checker(game, form)
    raws = lp.solve_blp_plans(form.poly, form.payoff, form.reach, tol, progress, check)
    final = check.final(raws)
    rounds = [
        Round(raw.value, _support_names(game, raw.support),
              {n: float(p) for n, p, s in zip(game.level_names, raw.adversary, raw.support) if s},
              _policy(form, raw.plan, tol), regret, raw.unique)
        for raw, regret in zip(raws, check.regrets)
    ]
    return BLPResult(rounds[0].value, rounds, rounds[-1].policy, final, check.optimal_return())


def _local_game(
    game: TreeGame, form: SequenceForm, info: int, policy: TreePolicy
) -> OneStepGame | None:
    """The one-step game at an information set, or None if no level reaches it.

    Its levels are the levels reaching the set; the reward of action ``a`` on level ``l`` is the
    expected return on ``l`` *conditional on* arriving there, playing ``a`` and then following
    ``policy`` (already defined on all later information sets).
    """
    aoh, names = form.infosets[info], form.infoset_actions[info]
    weight: dict[int, float] = {}
    total: dict[int, np.ndarray] = {}
    for level, prob, node in form.members[info]:
        if prob <= 0:
            continue
        values = np.array([node_value(node.children[a], aoh + (a,), policy) for a in names])
        weight[level] = weight.get(level, 0.0) + prob
        total[level] = total.get(level, 0.0) + prob * values
    if not weight:
        return None
    levels = sorted(weight)
    rewards = np.array([total[l] / weight[l] for l in levels])
    return OneStepGame(names, tuple(game.level_names[l] for l in levels),
                       (_describe(aoh),) * len(levels), rewards)


def local_mmr_policy(game: TreeGame) -> TreePolicy:
    """The locally minimax-regret policy (the paper's appendix counter-example to local regret).

    Information sets are processed backwards; at each, the one-step MMR of the game returned by
    :func:`_local_game` (regret measured against the best action under the continuation policy).
    Information sets reached by no level get the uniform distribution.
    """
    form = build_sequence_form(game)
    policy: TreePolicy = {}
    for info in reversed(range(len(form.infosets))):
        names = form.infoset_actions[info]
        local = _local_game(game, form, info, policy)
        probs = (np.full(len(names), 1.0 / len(names)) if local is None
                 else solve_onestep_mmr(local).policy[0])
        policy[form.infosets[info]] = dict(zip(names, map(float, probs)))
    return {aoh: policy[aoh] for aoh in form.infosets}


def one_step_to_tree(game: OneStepGame) -> TreeGame:
    """The same game as trees: one decision node per level, then terminal rewards."""
    trees = tuple(
        Decision(obs, {a: Terminal(float(r)) for a, r in zip(game.actions, rewards)})
        for obs, rewards in zip(game.observations, game.rewards)
    )
    return TreeGame(game.actions, game.level_names, trees)
