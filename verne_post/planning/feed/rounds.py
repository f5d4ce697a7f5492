"""The rounds of planning: TOPP2 under the caps, the time law, its verification, and the caps
lowered around every excess until each sequence is within every limit."""

from __future__ import annotations

import logging
from dataclasses import replace

import numpy as np

from ..timing import PlanningError
from ..topp import Engine, ToppError, solver
from .batch import Batch
from .grid import build_grid
from .plan import Cubics, FeedPlan
from .profiles import Profiles, peak_points, plateau_levels, time_laws
from .scurve import scurve_laws, scurve_profiles
from .segments import range_chmin
from .verification import block_times, verify

logger = logging.getLogger("verne_post.planning.feed_planner")  # the planner's one logger, as before the split

_ACC_MARGIN = 0.97  # share of the acceleration limits given to TOPP2 (the filter mixes neighbours)
# (acceleration factor, time-scale factor) tried in turn when the TOPP2 engine fails numerically
_RETRIES = ((1.0, 1.0), (0.999, 0.1), (0.99, 0.43), (0.98, 2.3), (0.97, 10.0))
# A jerk excess at least this large is taken for a turn without cruise (feed_planner's docstring, step 4):
# the filter doubles the jerk there, while other excesses are a few per cent.
_TURN_JERK = 1.3
_NARROWER = 0.9  # a turn's window is narrowed to its own ramp's if that is this much narrower

#: Per sequence still over a limit: its worst (velocity, acceleration, jerk) ratios and where (s).
Worst = dict[int, tuple[float, float, float, float]]


class Planner:
    """All the sequences of a batch: grid and caps once (:func:`build_grid`), then TOPP2, filter
    and verification in rounds (:mod:`.profiles`, :mod:`.verification`), each round over the
    sequences not yet within every limit."""

    def __init__(self, batch: Batch, engine: Engine, max_refinements: int, erode: float, widest: bool,
                 grid_factor: float = 1.0) -> None:
        self.batch, self.engine, self.solve, self.max_refinements = batch, engine, solver(engine), max_refinements
        self.erode = erode
        grid = build_grid(batch, erode, widest, grid_factor)
        self.grid, self.t_scale, self.widest, self.w = grid.points, grid.t_scale, grid.widest, grid.w
        self.scurve_floor, self.xcap, self.radius = grid.scurve_floor, grid.xcap, grid.radius
        self.need_acc, self.need_jerk, self.q1, self.q2 = grid.need_acc, grid.need_jerk, grid.q1, grid.q2
        self._acceleration_bound()

    def _acceleration_bound(self) -> None:
        """The path acceleration bound umax (1/s^2) at the gridpoints for the current widths."""
        need = self.need_acc
        if self.need_jerk is not None:
            need = np.maximum(need, self.need_jerk / self.w[self.grid.owner])
        with np.errstate(divide="ignore"):
            self.umax = np.minimum(1.0 / need, 1e300)

    # -- rounds ---------------------------------------------------------------------------------

    def plan(self) -> list[FeedPlan | PlanningError]:
        count = self.batch.count
        results: list[FeedPlan | PlanningError | None] = [None] * count
        n = len(self.grid.start)
        cap = np.full(n, np.inf)
        acc_scale = np.full(n, _ACC_MARGIN if self.batch.jerk else 1.0)
        # The engines may exceed their bounds by rounding, and the filter mixes neighbouring speeds:
        # keep clear. 4e-5 left one sequence in six of the 105k job 2e-5 to 4e-5 over a cap,
        # each then planned again with its caps 3 % lower there (slower, and a round of planning more).
        base = self.xcap * (1.0 - 3e-4)
        x = np.zeros(n)
        active = np.arange(count)
        worst: Worst = {}
        narrowed, plateaued = np.zeros(count, bool), np.zeros(count, bool)
        scurves: dict[int, FeedPlan] = {}
        for attempt in range(self.max_refinements + 1):
            solved = []
            xmax = np.minimum(base, cap)
            for r in active:
                outcome = self.topp(int(r), xmax, acc_scale)
                if isinstance(outcome, PlanningError):
                    results[r] = outcome
                else:
                    x[self.grid.first[r]:self.grid.first[r + 1]] = outcome
                    solved.append(r)
            if not solved:
                break
            profiles, stuck = time_laws(self.grid, self.batch, self.w, np.array(solved), x)
            for r, error in stuck.items():
                results[r] = error
            times, broken = block_times(self.batch, profiles)
            for r, error in broken.items():
                results[r] = error
            good = ~np.isin(profiles.seqs, list(broken))
            where, fx, fa, seq, ratios, peaks = verify(self.batch, self.widest, profiles, times, good)
            failing = np.unique(seq)
            for k in np.flatnonzero(good & ~np.isin(profiles.seqs, failing)):
                results[profiles.seqs[k]] = self.feed_plan(int(profiles.seqs[k]), profiles, int(k), times, attempt,
                                                            peaks[k])
            if attempt == 0 and self.batch.jerk:
                # A sequence within every limit has its plan; one still over a limit only slows
                # down in later rounds: its S-curve, if faster than this round, ends its rounds, or
                # else may still win at the end (tried where it may beat 1.25 times this round:
                # the later rounds cost the 105k job's re-orientations 2 to 8 %).
                over = np.isin(profiles.seqs, failing)
                scurves = self._scurve_plans(profiles.seqs[good], (np.where(over, 1.25, 1.0) * profiles.total)[good])
                first = dict(zip(profiles.seqs.tolist(), profiles.total.tolist(), strict=True))
                done = [r for r in failing.tolist() if r in scurves and scurves[r].total <= first[r]]
                for r in done:
                    results[r] = scurves.pop(r)
                failing = np.setdiff1d(failing, done)
            if not len(failing):
                break
            cap, acc_scale = self._lower(failing, (where, fx, fa, seq, ratios), x, cap, acc_scale, worst, narrowed,
                                         plateaued)
            logger.debug("feed plan round %d: %d sequences over the limits", attempt, len(failing))
            active = failing
        kinds = ("velocity or feed", "acceleration", "jerk")
        for r, (*ratio, at) in worst.items():
            if results[r] is None:
                kind = kinds[int(np.argmax(ratio))]
                index = self.batch.waypoint_at(r, at)
                results[r] = PlanningError(
                    f"no time law within the joint {kind} limits found near waypoint {index} after "
                    f"{self.max_refinements} refinements (worst ratio {max(ratio):.3f}): the jerk/acceleration "
                    f"limits cannot be met along this path", index)
        for r, plan in scurves.items():  # verified too: also where the filtered plan found none
            if not isinstance(results[r], FeedPlan) or plan.total < results[r].total:  # type: ignore[union-attr]
                results[r] = plan
        assert all(result is not None for result in results)
        return results  # type: ignore[return-value]

    def _lower(self, failing: np.ndarray, excess: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
               x: np.ndarray, cap: np.ndarray, acc_scale: np.ndarray, worst: Worst,
               narrowed: np.ndarray, plateaued: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """After a round: the caps and acceleration scales lowered around every excess of the
        ``failing`` sequences (``excess`` as :func:`.verification.verify` finds it), a turn
        without cruise narrowed or given a plateau; ``worst``, ``narrowed`` and ``plateaued``
        are updated in place. Returns the new caps and acceleration scales."""
        where, fx, fa, seq, ratios = excess
        count, n = self.batch.count, len(self.grid.start)
        for r in failing:
            mine = seq == r
            top = int(np.argmax(np.max(ratios[mine], axis=1)))
            worst[int(r)] = (*ratios[mine][top], float(where[mine][top]))
        # Lower the caps and the acceleration bound around each violation, in proportion, over
        # the stretch the filter window there can span (twice the erosion radius, and the
        # neighbouring gridpoints).
        grid = self.grid
        nearest = np.clip(grid.search(seq, where), grid.first[seq] + 1, grid.first[seq + 1] - 1)
        reach = 2.0 * np.maximum(self.radius[nearest], self.radius[nearest - 1])
        lo = grid.clip(seq, grid.search(seq, where - reach, "left") - 1)
        hi = grid.clip(seq, grid.search(seq, where + reach, "right"))
        fx_grid = np.minimum(range_chmin(n, lo, hi, fx), 1.0)
        fa_grid = np.minimum(range_chmin(n, lo, hi, fa), 1.0)
        cap = np.minimum(cap, np.where(fx_grid < 1.0, fx_grid * np.maximum(x, 0.0), np.inf))
        # A turn without cruise (feed_planner's docstring, step 4): a plateau, not a lower acceleration.
        turns = np.array([r for r in failing if worst[int(r)][2] >= _TURN_JERK and not plateaued[r]], dtype=int)
        if len(turns):
            # A peak too slow to need full acceleration wants a narrower window first (the
            # time-optimal ramp to V has w = sqrt(V / J)); its plateau comes the round after.
            peak = peak_points(grid, x, turns)
            ramp = np.sqrt(np.max(np.abs(self.q1[peak]) * np.sqrt(np.maximum(x[peak], 0.0))[:, None]
                                  / self.batch.limits.jerk, axis=1))
            narrower = (ramp < _NARROWER * self.w[turns]) & ~narrowed[turns]
            if np.any(narrower):
                self.w[turns[narrower]] = ramp[narrower]
                narrowed[turns[narrower]] = True
                self._acceleration_bound()
                fa_grid[np.isin(grid.owner, turns[narrower])] = 1.0
                turns = turns[~narrower]
        if len(turns):
            level = np.full(count, np.nan)
            level[turns] = plateau_levels(grid, x, turns, self.w[turns])
            plateaued[turns] = True
            on_plateau = np.isfinite(level)[grid.owner]
            cap[on_plateau] = np.minimum(cap[on_plateau], level[grid.owner[on_plateau]])
            fa_grid[on_plateau] = 1.0
        return cap, acc_scale * fa_grid

    def _scurve_plans(self, seqs: np.ndarray, planned: np.ndarray) -> dict[int, FeedPlan]:
        """Verified S-curves along the paths of the sequences ``seqs`` (:func:`scurve_laws`) that
        are faster than ``planned`` (s, each); only sequences whose lowest cap allows that are tried."""
        hopeful = self.scurve_floor[seqs] < planned
        seqs, planned = seqs[hopeful], planned[hopeful]
        if not len(seqs):
            return {}
        durations, jerks = scurve_laws(self.batch, seqs)
        faster = np.flatnonzero(np.sum(durations, axis=1) < planned)
        if not len(faster):
            return {}
        profiles = scurve_profiles(seqs[faster], durations[faster], jerks[faster])
        times, broken = block_times(self.batch, profiles)
        good = ~np.isin(profiles.seqs, list(broken))
        _, _, _, failing, _, peaks = verify(self.batch, self.widest, profiles, times, good)
        plans = {}
        for k in np.flatnonzero(good & ~np.isin(profiles.seqs, failing)):
            r = int(profiles.seqs[k])
            plans[r] = replace(self.feed_plan(r, profiles, int(k), times, 0, peaks[k]),
                               filter_width=float(durations[faster[k], 0]), gridpoints=0)
        return plans

    def topp(self, r: int, xmax: np.ndarray, acc_scale: np.ndarray, filtered: bool = True
              ) -> np.ndarray | PlanningError:
        """Squared path speeds (1/s^2) at the gridpoints of sequence r, time-optimal under xmax
        and the accelerations (and, to be ``filtered``, the path acceleration bound umax).

        An engine may lose a reachable set to rounding; the same problem is then solved again at
        another time scale, with the acceleration limits 0.1 to 2 % lower (stricter, never looser).
        """
        g = slice(self.grid.first[r], self.grid.first[r + 1])
        failure = None
        for tighten, rescale in _RETRIES:
            t0 = self.t_scale[r] * rescale
            scale = acc_scale[g] * tighten
            inverse = 1.0 / (scale[:, None] * self.batch.limits.acceleration[None, :] * t0 ** 2)
            umax = scale * self.umax[g] * t0 ** 2 if self.batch.jerk and filtered else None
            try:
                x = self.solve(self.grid.start[g], np.maximum(xmax[g], 0.0) * t0 ** 2, umax, self.q1[g] * inverse,
                               self.q2[g] * inverse) / t0 ** 2
            except ToppError as error:
                failure = error
                logger.debug("%s failed (accelerations x %s, time scale x %s): %s", self.engine, tighten, rescale,
                             error)
                continue
            x[0] = x[-1] = 0.0
            return x
        where = 0 if failure is None or failure.index is None else self.batch.waypoint_at(
            r, float(self.grid.start[g][min(failure.index, g.stop - g.start - 1)]))
        return PlanningError(f"{self.engine} found no feasible time law near waypoint {where} (instance not "
                             f"controllable or numerically ill-conditioned)", where)

    # -- the time law ---------------------------------------------------------------------------

    def feed_plan(self, r: int, profiles: Profiles, k: int, times: tuple[np.ndarray, np.ndarray],
                   attempt: int, peaks: np.ndarray) -> FeedPlan:
        batch = self.batch
        block_times = times[0][times[1][k]:times[1][k + 1]].copy()
        b0, b1 = profiles.bfirst[k], profiles.bfirst[k + 1]
        profile = Cubics(profiles.breaks[b0:b1].copy(), np.ascontiguousarray(profiles.coef[:, b0 - k:b1 - k - 1]))
        return FeedPlan(np.diff(block_times), block_times, *batch.sequence_path(r), profile, float(self.w[r]),
                        int(self.grid.first[r + 1] - self.grid.first[r]), attempt, peaks)
