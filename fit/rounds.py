"""Rounds of starts: which cases of a batch take another round, from where, in calls of how many cases, and
every start the cases have taken (docs/fit.md, "More starts until the answer repeats" and "Where the rounds can
stop short"). ``reconstruction.reconstruct_batch`` runs the rounds; each is a call of ``rows.run_rows``."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ks_jax.model.types import OK

from .rows import RowFits, best_start, count_at_best
from .uncertainty import AT_BOUND, CHI2_Z, chi2_quantile


MORE_STARTS = 8  # by default a fit takes up to this many rounds of ``starts`` starts (``settled``)
AGREE = 2  # starts that must reach the best fit before a fit takes no more starts


def settled(cost, dof):
    """Which cases' starts so far (``cost`` (B, S): each start's cost, inf where a case has no such start) found
    a fit it can keep: the best cost reached by ``AGREE`` starts or more, with a chi^2 within its distribution's
    99% quantile (``dof`` (B,): the evidence's count plus the priors' less the unknowns' degrees of freedom). A
    fit that no start can evaluate is settled: more starts would not help it."""
    finite = np.isfinite(cost)
    chi2 = 2.0 * np.where(finite, cost, np.inf).min(axis=1)
    return ~finite.any(axis=1) | ((count_at_best(cost) >= AGREE) & (chi2 <= chi2_quantile(np.maximum(dof, 1), CHI2_Z)))


# the slide-side starts' friction, in parts of the friction needed to stick
SLIDE_SIDE = 1.0 - np.geomspace(0.02, 0.6, 8)
OFF_BOUND = np.linspace(0.1, 0.9, 8)  # the off-bound starts of an unknown pinned at a bound, in parts of its range


def other_side(best: RowFits, problem, lo, hi, pw, count: int):
    """Starts from kept fits where the rounds of starts can stop short of the best fit: (cases (K,), x (K,
    ``count``, n)), for the cases (of B) whose best fit (``best``: its x (B, n), status, sliding, stick_ratio
    (B,), in the fit's coordinates; ``lo``, ``hi``, ``pw`` (B, n)) is in such a place:

    - The contact sticks (friction an unknown without a prior, needed above its lower bound): the best fit with
      the friction at ``SLIDE_SIDE`` parts of what it needs. A contact that sticks has one cost for every
      friction above the one it needs (a flat plateau), so every start that reaches the plateau agrees on its
      cost; a sliding fit just below the edge, which the evidence may prefer, is reached only from that side.
    - Unknowns without a prior pinned at a bound: the best fit with each of them in turn at ``OFF_BOUND`` parts
      of its range. Starts that end against the same bound agree on its cost too, where a fit inside the
      bounds (a restitution that trades against the speeds) can be better.

    A best fit without an exchange is in neither."""
    x0 = np.asarray(best.x, np.float64)
    ok = np.asarray(best.status) == OK
    free = np.asarray(pw) <= 0
    x = np.repeat(x0[:, None], count, axis=1)
    stick = np.zeros(len(x0), bool)
    if "contact.friction" in problem.unknowns:
        j = problem.unknowns.index("contact.friction")
        needed = np.abs(np.asarray(best.stick_ratio, np.float64))
        stick = ok & ~np.asarray(best.sliding, bool) & free[:, j] & (needed > lo[:, j])
        x[stick, :, j] = lo[stick, j, None] + np.resize(SLIDE_SIDE, count) * (needed - lo[:, j])[stick, None]
    width = hi - lo
    with np.errstate(invalid="ignore"):  # inf - inf where a bound is missing: not pinned
        pinned = free & np.isfinite(width) & (width > 0) & (np.minimum(x0 - lo, hi - x0) <= AT_BOUND * width)
    pinned_cases = ok & ~stick & pinned.any(axis=1)
    for i in np.flatnonzero(pinned_cases):
        js = np.flatnonzero(pinned[i])
        for k in range(count):
            j = js[k % len(js)]
            x[i, k, j] = lo[i, j] + OFF_BOUND[(k // len(js)) % len(OFF_BOUND)] * width[i, j]
    cases = np.flatnonzero(stick | pinned_cases)
    return cases, x[cases]


MORE_BLOCKS = (8, 64)  # cases per call of a further round of starts on a CPU: a few row counts, a program each


def more_block(cases: int, todo: int, starts: int) -> int:
    """Rows per call of a further round of starts for ``todo`` of ``cases`` cases on the CPU's path (an
    accelerator's runs every round in the fit's own block: ``rows.fit_block``): the least of ``MORE_BLOCKS`` cases
    (at most ``cases``) that holds them all, else the largest. A CPU runs a call's rows one after another and a
    vmapped solver runs every row until its slowest converges, so a round of a few cases of a large batch is not
    padded to hundreds of rows, and calls of 64 cases cost what one call of them all does; the fixed counts keep
    the compiled programs to a few."""
    sizes = sorted({min(c, cases) for c in MORE_BLOCKS})
    return next((c for c in sizes if c >= todo), sizes[-1]) * starts


class Table(NamedTuple):
    """Per start of every case of a batch, (B, S): the few numbers the rounds decide on (``RowFits``' of the same
    names; cost inf, converged False, ... where a case has no such start), and ``present``: it has."""

    cost: np.ndarray
    converged: np.ndarray
    stalled: np.ndarray
    status: np.ndarray
    sliding: np.ndarray
    stick_ratio: np.ndarray
    present: np.ndarray


# each field's value where a case took no start in a round
ABSENT = Table(cost=np.inf, converged=False, stalled=False, status=-1, sliding=False, stick_ratio=np.nan,
               present=False)


class Starts:
    """Every start a batch's cases have taken, round by round: per start, the few numbers the rounds decide on
    (``table``, a ``Table`` (B, S) with S growing by a round's starts), and each round's solver outputs for the
    cases it fitted, from which ``best`` gathers the best start's whole row."""

    def __init__(self, out: RowFits):
        B, S = out.cost.shape
        self.per_round = S
        self.count = np.full(B, S)
        self.table = Table(*(np.asarray(getattr(out, k)) for k in Table._fields[:-1]), np.ones((B, S), bool))
        self.rounds = [(np.arange(B), out)]

    def add(self, cases, out: RowFits):
        """A round's outputs (``run_rows``'s, (T, S, ...)) for ``cases`` (T,)."""
        B = len(self.count)
        columns = []
        for k, fill, kept in zip(Table._fields, ABSENT, self.table):
            column = np.full((B, self.per_round), fill, dtype=kept.dtype)
            column[cases] = True if k == "present" else getattr(out, k)
            columns.append(np.concatenate([kept, column], axis=1))
        self.table = Table(*columns)
        self.count[cases] += self.per_round
        self.rounds.append((cases, out))

    def best(self, cases, keys=RowFits._fields) -> RowFits:
        """The best start's outputs (``keys``, default all; the others None) of ``cases`` (K,): arrays (K, ...)."""
        b = best_start(self.table.cost[cases], self.table.converged[cases])
        r, s = np.divmod(b, self.per_round)
        first = self.rounds[0][1]
        out = {k: np.empty((len(cases), *getattr(first, k).shape[2:]), getattr(first, k).dtype) for k in keys}
        for n, (members, o) in enumerate(self.rounds):
            take = np.flatnonzero(r == n)
            if take.size:
                at = np.searchsorted(members, cases[take])  # a round's cases are in increasing order
                for k in out:
                    out[k][take] = getattr(o, k)[at, s[take]]
        return RowFits(**out)
