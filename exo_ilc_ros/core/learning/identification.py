"""Between-trial identification of the patient's joint forces: eq (6)'s Q^v, Q^c, Q^f (viscous
friction, joint stiffness, Coulomb friction), which the paper sets to zero, and the stretch reflex,
per joint, from one trial's commanded effort and measured position, recursive over trials.

The model, per joint j (the virtual patient's, :mod:`exo_ilc_ros.core.loop.patient`), with the arm's
own dynamics of eq (8) written in Lagrange's form so that no acceleration is needed::

    u_j(t - d T) = p_j' + w_j + tau_p,j,   p = a_N(q) qdot,
    w_j = -1/2 qdot^T (d a_N / d q_j) qdot - Q^g_j,
    tau_p,j = B qdot_j + F_c tanh(qdot_j / v_s) + K q_j + c + delta (p_j' + w_j)
              + G sgn(v) max(0, abs(v) - v_th),   v = qdot_j(t - tau_r),
              [- K_v L[q_d,j - q_j] - D_v L[qdot_d,j - qdot_j]]

(a_N, Q^g the nominal model's eqs (2) and (6); p_j' + w_j equals a_N qddot + c_N of eq (7),
tested) with K (q_j - q_0) = K q_j + c, so q_0 = -c / K; delta: the plant's mass error along
the nominal torque (a uniform mass error, eq (15), is exactly this term); d: the actuator's
delay in control periods, known. The reflex (G, v_th, tau_r) is held over each period, as the
virtual patient holds it. The bracket, the patient's own effort toward the reference (L a
first-order lag), is fitted only with ``voluntary=True``; otherwise it tests the estimate.

**Filtered regressors** (state-variable filter): every signal passes through the same
H(s) = w_f^2 / (s + w_f)^2, so the derivative p' enters as (s H)[p], a proper filter of p, and
qdot_j's column as (s H)[q_j]: no acceleration, and no velocity where a position does. The
nonlinear columns (tanh, reflex) and p, w are built from a zero-phase low-passed position (the
whole trial is at hand between trials) and its central difference, then filtered by H; the
measured velocity is not used (its filter may lag). The held effort and the held reflex are
filtered by H's zero-order-hold discretisation, the smooth signals by its first-order-hold one;
every filter starts at rest at its signal's first value.

**Recursive least squares over trials** in information form (per joint; forgetting once per
trial, lambda in (0, 1]): R_k = lambda R_{k-1} + Phi_k^T Phi_k, b_k = lambda b_{k-1} +
Phi_k^T y_k, theta_k = R_k^-1 b_k. A trial whose own regressor is ill-conditioned is added
without forgetting (no wind-up of the directions it does not excite). The reflex's threshold and
delay enter nonlinearly: the information of every (v_th, tau_r) on a grid is kept, and the one of
least residual wins (separable least squares); G is linear.

**Confidence**: Cov(theta) = s^2 R^-1 (sum lambda^2m / sum lambda^m), s^2 = RSS / (n - p),
each variance inflated by the last trials' ratio of the autocorrelation-robust (Newey-West,
Bartlett kernel) to the naive variance (filtered residuals are strongly autocorrelated).
**Model error** (``reversal_speed`` > 0; 0 trusts the tanh law): the trial refitted with a hard
Coulomb law, sgn(qdot) for the tanh, moves the estimate by d; Cov + d d^T (lambda-weighted over
trials) gives the 95 % intervals +-1.96 SE; q_0's by the delta method; v_th's and tau_r's from
the residual's profile over the grid.
**Trust** (the precision rule reads the noise's SE alone): the condition number of the
column-scaled information matrix,
each parameter's variance inflation (collinearity), excitation, precision and physical bounds,
and no sign of the patient's own effort in the residual (:class:`IdentificationSettings`); an
estimate that fails any of them says why and is not usable (:attr:`JointEstimate.trustworthy`).
A trial with non-finite samples, or where any joint moved faster than the regression resolves
(chatter, which biases every coupled joint), is refused and changes nothing.

**Separability** (``reversal_speed`` > 0): Coulomb friction is fitted only from the samples
where the joint moved faster than ``reversal_speed`` (for the filter's memory), where a smooth
and a hard law agree; on a joint that never did so in both directions F_c sgn(qdot) is a
constant of the movement, so it is left out and the offset carries c + F_c sgn(qdot)
(:attr:`JointEstimate.absorbed`, :attr:`ParameterEstimate.combined_with`); every pair whose
estimates correlate by more than ``max_correlation`` is reported
(:attr:`JointEstimate.inseparable`, :func:`inseparable_pairs`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from ..arm.model import ArmModel
from ..loop.record import TrialRecord
from .identification_settings import (
    BASE_PARAMETERS,
    KEEP_ORDER,
    PASSIVE_PARAMETERS,
    Z95,
    IdentificationSettings,
    judge,
)
from .joint_force_regressors import (
    RegressionFilters,
    TrialRegressors,
    project_out,
    reflex_columns,
    trial_regressors,
)
from .patient_estimate import PARAMETERS, JointEstimate, ParameterEstimate, PatientEstimate
from .recursive_least_squares import (
    JointInformation,
    Solution,
    conditioning,
    hac_inflation,
    law_difference,
    solve_scaled,
)
from .separability import inseparable_pairs, inseparable_reason, most_correlated

__all__ = ["JointForceIdentifier", "inseparable_pairs"]


class JointForceIdentifier:
    """Identifies the patient's joint forces trial by trial (module docstring): feed every
    trial's measured position and commanded effort to :meth:`update`."""

    def __init__(self, nominal: ArmModel, settings: IdentificationSettings | None = None) -> None:
        self.nominal = nominal
        self.settings = settings or IdentificationSettings()
        self.filters = RegressionFilters(self.settings)
        self.thresholds = np.asarray(self.settings.reflex_thresholds, dtype=float)
        self.delays = self.settings.delay_samples
        grid = len(self.delays) * self.thresholds.shape[0] if self.settings.reflex else 0
        self.fitted = np.array([name in PASSIVE_PARAMETERS or self.settings.voluntary
                                for name in BASE_PARAMETERS])
        self.joints = [JointInformation(grid, self.fitted) for _ in range(nominal.dof)]
        self.moving = [JointInformation(grid, self.fitted) for _ in range(nominal.dof)]
        """Per joint, the information of the samples where the joint moved faster than
        ``reversal_speed`` (and had for the filter's memory): where a smooth and a hard
        Coulomb law agree. A joint that never reversed is fitted from these alone, with the
        offset carrying F_c sgn(qdot) (:meth:`_information`)."""
        self.estimate: PatientEstimate | None = None
        """The latest estimate (None before the first trial)."""
        self._trial = 0

    def update_record(self, record: TrialRecord) -> PatientEstimate:
        """:meth:`update` with a trial's record (measured position, commanded effort, its
        reference). An aborted trial is used whole: the arm's dynamics hold through the safe
        hold too (a hold that chatters is refused like any chattering trial)."""
        return self.update(record.position, record.effort, record.trial,
                           (record.reference.position, record.reference.velocity))

    def update(self, position: np.ndarray, effort: np.ndarray, trial: int | None = None,
               reference: tuple[np.ndarray, np.ndarray] | None = None) -> PatientEstimate:
        """Add one trial's samples, (N+1, n) each, and return the estimate after it;
        ``reference``: the (q_d, qdot_d) it tracked (for the patient's own effort). A trial
        whose samples are unusable (wrong shape, non-finite, too short, chatter) changes
        nothing: the estimate says why in ``rejected``."""
        self._trial = int(trial) if trial is not None else self._trial + 1
        q = np.asarray(position, dtype=float)
        u = np.asarray(effort, dtype=float)
        n = self.nominal.dof
        s = self.settings
        minimum = int(round(s.burn_in / s.period)) + 4 * len(BASE_PARAMETERS) + 30
        why = ""
        if q.ndim != 2 or q.shape[1] != n or u.shape != q.shape:
            why = (f"position and effort must both be (samples, {n}), got {q.shape} and "
                   f"{u.shape}")
        elif q.shape[0] < minimum:
            why = f"{q.shape[0]} samples, at least {minimum} are needed"
        elif not (np.all(np.isfinite(q)) and np.all(np.isfinite(u))):
            why = "the samples hold non-finite values"
        elif reference is not None and not (
                np.shape(reference[0]) == q.shape and np.shape(reference[1]) == q.shape
                and np.all(np.isfinite(reference[0])) and np.all(np.isfinite(reference[1]))):
            why = f"the reference must be finite and {q.shape}"
        if why:
            return self._conclude(f"trial {self._trial} not used: {why}")
        reg = trial_regressors(self.nominal, s, q, u, self.filters, reference)
        fast = np.flatnonzero(reg.unresolved > s.max_unresolved_motion)
        if fast.size:
            j = int(fast[np.argmax(reg.unresolved[fast])])
            return self._conclude(
                f"trial {self._trial} not used: joint {j} moved faster than the regression "
                f"resolves ({reg.unresolved[j]:.2g} rad RMS above {s.smoothing_cutoff:g} Hz > "
                f"{s.max_unresolved_motion:g}: chatter or stick-slip), which biases every "
                "joint coupled to it")
        reflexes = []
        rows = []
        memory = int(math.ceil(6.0 / (s.filter_bandwidth * s.period)))
        for j, info in enumerate(self.joints):
            phi = np.ascontiguousarray(reg.base[:, j, :])
            y = np.ascontiguousarray(reg.target[:, j])
            v = np.ascontiguousarray(reg.velocity[:, j])
            reflex, active = self._reflex(v, reg)
            reflexes.append((reflex, active))
            condition, excited = conditioning(phi.T @ phi, phi.T @ y, self.fitted)
            well = condition <= s.max_condition and bool(np.all(excited[:4]))
            lam = s.forgetting if well else 1.0
            info.add(phi, reflex, active, y, lam, v, float(reg.unresolved[j]))
            slow = (np.abs(v) < s.reversal_speed).astype(float)
            fast = (np.convolve(slow, np.ones(memory + 1))[:v.shape[0]] == 0.0)[reg.skip:]
            rows.append(fast)
            self.moving[j].add(phi[fast], reflex[fast], active, y[fast], lam, v,
                               float(reg.unresolved[j]))
        estimate = self._conclude("")
        for j, info in enumerate(self.joints):
            self._update_inflation(j, info, reg, reflexes[j], estimate.joints[j], None)
            self._update_inflation(j, self.moving[j], reg, reflexes[j], estimate.joints[j],
                                   rows[j])
        self.estimate = self._conclude("")
        return self.estimate

    def _reflex(self, velocity: np.ndarray,
                reg: TrialRegressors) -> tuple[np.ndarray, np.ndarray]:
        """The reflex columns of the grid points whose threshold this trial's stretch exceeds
        (the others are zero), and their grid indices."""
        width = self.thresholds.shape[0]
        if not self.settings.reflex:
            return np.zeros((reg.target.shape[0], 0)), np.zeros(0, dtype=int)
        below = np.flatnonzero(self.thresholds < np.max(np.abs(velocity)))
        active = (np.arange(len(self.delays))[:, None] * width + below[None, :]).ravel()
        cols = reflex_columns(velocity, self.thresholds[below], self.delays, self.filters,
                              reg.skip)
        return project_out(cols, reg.transients), active

    # --- estimation -------------------------------------------------------------------------

    def _conclude(self, rejected: str) -> PatientEstimate:
        joints = tuple(self._joint(j, self._information(j)) for j in range(len(self.joints)))
        estimate = PatientEstimate(self._trial, joints, rejected)
        if rejected:
            self.estimate = estimate
        return estimate

    def _information(self, j: int) -> JointInformation:
        """The information joint ``j`` is fitted from: of its fast samples alone
        (:attr:`moving`) when Coulomb friction is fitted, the joint never moved faster than
        ``reversal_speed`` in both directions, and it did in one for at least 1 s of samples
        (forgotten as the rest); else of every sample."""
        info, moving = self.joints[j], self.moving[j]
        coulomb = BASE_PARAMETERS.index("coulomb")
        if bool(info.fitted[coulomb]) and moving.samples * self.settings.period >= 1.0:
            return moving
        return info

    def _separate(self, info: JointInformation
                  ) -> tuple[np.ndarray, tuple[tuple[str, str, float], ...]]:
        """:meth:`_separation`, once per trial and joint information."""
        mask, pairs = info.derived("separate", lambda: self._separation(info))
        return mask.copy(), pairs

    def _separation(self, info: JointInformation
                    ) -> tuple[np.ndarray, tuple[tuple[str, str, float], ...]]:
        """The base columns fitted (``info.fitted`` less those the trials cannot separate from
        another) and the pairs found, (kept, left out, correlation; nan: by the movement's
        shape). Then (``reversal_speed`` > 0 only), one at a time, the less needed
        (:data:`KEEP_ORDER`) of the most correlated pair above ``max_correlation``
        (:func:`inseparable_pairs`). ``info`` the fast samples of a joint that never reversed
        (:meth:`_information`): Coulomb friction left out, the offset carries it."""
        s = self.settings
        names = BASE_PARAMETERS
        mask = info.fitted.copy()
        pairs: list[tuple[str, str, float]] = []
        coulomb = names.index("coulomb")
        if mask[coulomb] and info.R[coulomb, coulomb] > 0.0 \
                and float(np.min(info.fastest)) < s.reversal_speed:
            if any(info is moving for moving in self.moving):
                pairs.append(("offset", "coulomb", math.nan))
                mask[coulomb] = False
            else:  # too slow for either: both reported, neither left out
                pairs.append(("viscous", "coulomb", math.nan))
        for _ in range(len(names) if s.reversal_speed > 0.0 else 0):
            solution = info.solve(mask)
            found = [pair for pair in inseparable_pairs(solution.covariance_scaled, names,
                                                        s.max_correlation)
                     if "coulomb" in pair[:2]]
            if not found:
                break
            a, b, r = found[0]
            keep, drop = sorted((a, b), key=KEEP_ORDER.index)
            pairs.append((keep, drop, r))
            mask[names.index(drop)] = False
        solution = info.solve(mask)
        pairs += [(a, b, r) for a, b, r in inseparable_pairs(solution.covariance_scaled, names,
                                                             s.max_correlation)]
        return mask, tuple(pairs)

    def _selected(self, info: JointInformation, mask: np.ndarray
                  ) -> tuple[int | None, Solution, Solution]:
        """The best reflex grid point (None: no reflex column), its solution, the base one
        (the base columns of ``mask``); once per trial, information and mask."""
        return info.derived(("selected", mask.tobytes()),
                            lambda: self._selection(info, mask.copy()))

    def _selection(self, info: JointInformation, mask: np.ndarray
                   ) -> tuple[int | None, Solution, Solution]:
        base = info.solve(mask)
        if info.Rgg.shape[0] == 0 or info.trials == 0:
            return None, base, base
        rss = info.grid_rss()
        best = int(np.argmin(rss))
        if not np.isfinite(rss[best]):
            return None, base, base
        p = info.R.shape[0]
        R = np.zeros((p + 1, p + 1))
        R[:p, :p] = info.R
        R[p, :p] = R[:p, p] = info.Rxg[best]
        R[p, p] = info.Rgg[best]
        b = np.append(info.b, info.bg[best])
        return best, solve_scaled(R, b, info.yy, np.append(mask, True)), base

    def _update_inflation(self, j: int, info: JointInformation, reg: TrialRegressors,
                          reflex: tuple[np.ndarray, np.ndarray],
                          estimate: JointEstimate, rows: np.ndarray | None) -> None:
        """The autocorrelation inflation of the variances, from this trial's residual under
        the model now reported, and the friction law's model error (both lambda-weighted means
        over trials); ``rows``: the samples ``info`` holds (None: all)."""
        mask, _ = self._separate(info)
        best, chosen, _ = self._selected(info, mask)
        phi = reg.base[:, j, :]
        target = reg.target[:, j]
        p = phi.shape[1]
        if estimate.reflex_detected and best is not None:
            columns, active = reflex
            where = np.flatnonzero(active == best)
            col = columns[:, where[0]] if where.size else np.zeros(phi.shape[0])
            phi = np.column_stack([phi, col])
            theta = chosen.theta
        else:
            theta = info.solve(mask).theta
        if rows is not None:
            phi, target = phi[rows], target[rows]
        use = np.isfinite(theta)
        if not np.any(use) or phi.shape[0] <= p + 1:
            return
        residual = target - phi[:, use] @ theta[use]
        lags = int(math.ceil(4.0 / (self.settings.filter_bandwidth * self.settings.period)))
        new = np.full(p + 1, np.nan)
        new[np.flatnonzero(use)] = hac_inflation(phi[:, use], residual, lags)
        lam = self.settings.forgetting
        old = info.inflation
        weight_old = lam * (info.w1 - 1.0)
        shift = np.zeros(p + 1)
        coulomb = BASE_PARAMETERS.index("coulomb")
        if use[coulomb] and self.settings.reversal_speed > 0.0:  # 0: the tanh law trusted
            hard = reg.hard_coulomb[:, j] if rows is None else reg.hard_coulomb[rows, j]
            fitted = np.flatnonzero(use)
            shift[fitted] = law_difference(phi[:, use], target,
                                           int(np.searchsorted(fitted, coulomb)), hard)
        if np.all(np.isfinite(shift)):  # else (no solve) the earlier trials' is kept
            info.model_covariance = ((weight_old * info.model_covariance
                                      + np.outer(shift, shift)) / (weight_old + 1.0))
        mixed = np.where(np.isfinite(old), (weight_old * old + new) / (weight_old + 1.0), new)
        info.inflation = np.where(np.isfinite(mixed), mixed, old)

    def _joint(self, j: int, info: JointInformation) -> JointEstimate:
        s = self.settings
        if info.trials == 0:
            empty = {name: ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan,
                                             False, False, "no trial yet")
                     for name in PARAMETERS}
            return JointEstimate(j, empty, False, math.inf, math.nan, 0.0, 0, False,
                                 ("no trial yet",))
        mask, pairs = self._separate(info)
        absorbed = {drop: keep for keep, drop, _ in pairs
                    if not mask[BASE_PARAMETERS.index(drop)]}
        slow = any(a == "viscous" and b == "coulomb" and math.isnan(r) for a, b, r in pairs)
        best, with_reflex, base = self._selected(info, mask)
        p = len(BASE_PARAMETERS)
        detected = False
        reflex_reason = ""
        if not s.reflex:
            reflex_reason = "reflex not identified (settings)"
        elif best is None:
            reflex_reason = (f"not identifiable: the stretch velocity ({info.peak_speed:.3g} "
                             f"rad/s) never exceeded a threshold of the grid "
                             f"(>= {self.thresholds[0]:.3g} rad/s)")
        else:
            reflex_reason = self._reflex_rejection(info, best, with_reflex, base)
            detected = not reflex_reason
        chosen = with_reflex if detected else base
        sigma2 = chosen.rss / max(info.samples - int(np.sum(chosen.excited)), 1.0)
        weights = info.w2 / info.w1
        inflation = info.inflation[:chosen.theta.shape[0]]
        inflation = np.where(np.isfinite(inflation), inflation, 1.0)
        scale = np.where(chosen.excited, chosen.scale, np.nan)
        cov = sigma2 * weights * chosen.covariance_scaled / np.outer(scale, scale)
        cov = cov * np.sqrt(np.outer(inflation, inflation))
        model = info.model_covariance[:scale.shape[0], :scale.shape[0]]
        vif = np.diag(chosen.covariance_scaled)
        theta = chosen.theta
        params: dict[str, ParameterEstimate] = {}
        names = (*BASE_PARAMETERS, "reflex_gain") if detected else BASE_PARAMETERS
        for k, name in enumerate(names):
            if name == "model_scale" and not s.model_scale:
                params[name] = ParameterEstimate(name, 0.0, 0.0, 0.0, 0.0, True, True,
                                                 "")
                continue
            if name.startswith("voluntary") and not s.voluntary:
                params[name] = ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan,
                                                 False, False, "not fitted (voluntary=False)")
                continue
            if name in absorbed:
                params[name] = ParameterEstimate(
                    name, math.nan, math.nan, math.nan, math.nan, False, False,
                    inseparable_reason(name, absorbed[name], pairs, info.fastest, s))
                continue
            params[name] = self._parameter(name, theta[k], cov[k, k], model[k, k],
                                           chosen.excited[k], vif[k], chosen.covariance_scaled,
                                           k, names)
            if name in ("viscous", "coulomb") and slow:
                params[name] = dataclasses.replace(
                    params[name], identifiable=False, trustworthy=False,
                    reason="not separately identifiable (damping and Coulomb friction): the "
                           f"joint never moved faster than {s.reversal_speed:g} rad/s in both "
                           "directions, nor for 1 s in one (a smooth Coulomb law is a "
                           "damping at these speeds, a hard one a constant)")
            carried = tuple(drop for drop, keep in absorbed.items() if keep == name)
            if carried:
                params[name] = dataclasses.replace(params[name], combined_with=carried)
        params["rest_position"] = self._rest_position(theta, cov, model, params)
        if detected and best is not None:
            params.update(self._reflex_grid(info, best, sigma2 * weights
                                            * float(inflation[p])))
        else:
            upper = math.nan
            if best is not None:
                g, se = self._stats(info, with_reflex, p)
                upper = max(g + Z95 * se, 0.0) if math.isfinite(g + se) else math.nan
            identifiable = not reflex_reason.startswith("not identifiable")
            params["reflex_gain"] = ParameterEstimate("reflex_gain", 0.0, math.nan, 0.0, upper,
                                                      identifiable, False, reflex_reason)
            for name in ("reflex_threshold", "reflex_delay"):
                params[name] = ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan,
                                                 False, False, reflex_reason)
        needed = [name for name in PASSIVE_PARAMETERS if name not in absorbed]
        if detected:
            needed += ["reflex_gain", "reflex_threshold", "reflex_delay"]
        reasons = [f"{name}: {params[name].reason}" for name in needed
                   if not params[name].trustworthy]
        if not math.isfinite(chosen.condition) or chosen.condition > s.max_condition:
            reasons.insert(0, f"condition number {chosen.condition:.3g} > {s.max_condition:g}")
        suspicion = self._voluntary_suspicion(info, best if detected else None, chosen,
                                              sigma2, mask | ~info.fitted)
        if suspicion:
            reasons.insert(0, suspicion)
        if info.unresolved > s.max_unresolved_motion:
            reasons.insert(0, f"the joint moved faster than the regression resolves "
                              f"({info.unresolved:.2g} rad RMS above {s.smoothing_cutoff:g} Hz "
                              f"> {s.max_unresolved_motion:g}: chatter or stick-slip)")
        rms = math.sqrt(chosen.rss / info.samples) if info.samples > 0 else math.nan
        return JointEstimate(j, params, detected, chosen.condition, rms, info.peak_speed,
                             info.trials, not reasons, tuple(reasons), pairs,
                             tuple(absorbed))

    def _voluntary_suspicion(self, info: JointInformation, best: int | None,
                             chosen: Solution, sigma2: float, columns: np.ndarray) -> str:
        """"" unless the voluntary columns are not fitted, yet would lower the residual
        significantly (chi^2_2(0.999) = 13.8, with the passive columns' autocorrelation
        inflation) and by more than ``voluntary_minimum_torque``: then a patient's own effort
        is likely in the passive estimate."""
        p = len(BASE_PARAMETERS)
        if self.settings.voluntary or info.trials == 0:
            return ""
        voluntary = ~info.fitted
        if not np.all(np.diag(info.R)[voluntary] > 0.0):
            return ""  # no reference given
        R, b = info.R, info.b
        mask = columns.copy()
        if best is not None:
            R = np.zeros((p + 1, p + 1))
            R[:p, :p] = info.R
            R[p, :p] = R[:p, p] = info.Rxg[best]
            R[p, p] = info.Rgg[best]
            b = np.append(info.b, info.bg[best])
            mask = np.append(mask, True)
        full = solve_scaled(R, b, info.yy, mask)
        inflation = info.inflation[:len(PASSIVE_PARAMETERS)]
        infl = float(np.nanmedian(inflation)) if np.any(np.isfinite(inflation)) else 1.0
        scale = sigma2 * max(infl, 1.0) * info.w2 / info.w1
        drop = (chosen.rss - full.rss) / scale if scale > 0.0 else 0.0
        explained = math.sqrt(max(chosen.rss - full.rss, 0.0) / max(info.samples, 1.0))
        if drop > 13.8 and explained > self.settings.voluntary_minimum_torque:
            return (f"the tracking error explains {explained:.2g} N m RMS of the residual, "
                    f"{drop:.3g} times chance (chi^2_2(0.999) = 13.8): the patient's own effort "
                    "is likely in the estimate (identify with voluntary=True, or on relaxed "
                    "trials)")
        return ""

    def _reflex_rejection(self, info: JointInformation, best: int, with_reflex: Solution,
                          base: Solution) -> str:
        """"" if the reflex at grid point ``best`` is detected, else why not: G excited, not
        collinear, its interval above 0, its torque at the fastest stretch above the minimum,
        the residual's drop significant (chi^2_3(0.999) = 16.3: G, v_th and tau_r are fitted)
        and v_th above the grid's lowest value (a reflex from zero speed on is damping)."""
        s = self.settings
        p = len(BASE_PARAMETERS)
        g, se = self._stats(info, with_reflex, p)
        threshold = float(self.thresholds[best % self.thresholds.shape[0]])
        torque = g * max(info.peak_speed - threshold, 0.0)
        vif = float(with_reflex.covariance_scaled[p, p])
        if not (math.isfinite(g) and math.isfinite(se)):
            return "not identifiable: the reflex column is not excited"
        if not vif <= s.max_variance_inflation:
            names = (*BASE_PARAMETERS, "reflex_gain")
            return (f"no reflex detected: G not identifiable (variance inflation {vif:.3g}, "
                    f"collinear with {most_correlated(with_reflex.covariance_scaled, p, names)})")
        if g - Z95 * se <= 0.0:
            return f"no reflex detected: G = {g:.3g} +- {Z95 * se:.2g} N m s/rad includes 0"
        if torque < s.reflex_minimum_torque:
            return (f"no reflex detected: its torque at the fastest stretch ({torque:.3g} N m) "
                    f"is below {s.reflex_minimum_torque} N m")
        sigma2 = with_reflex.rss / max(info.samples - p - 1, 1.0)
        infl = info.inflation[p] if math.isfinite(info.inflation[p]) else 1.0
        drop = (base.rss - with_reflex.rss) / (sigma2 * infl * info.w2 / info.w1)
        if not drop > 16.3:
            return (f"no reflex detected: it lowers the residual by only {drop:.3g} "
                    "(chi^2_3(0.999) = 16.3)")
        grid = self._reflex_grid(info, best, sigma2 * infl * info.w2 / info.w1)
        if grid["reflex_threshold"].low <= self.thresholds[0]:
            return (f"no reflex detected: its threshold (v_th <= "
                    f"{grid['reflex_threshold'].high:.3g} rad/s) is not distinguishable from "
                    f"{self.thresholds[0]:g} rad/s (a reflex from rest on is damping)")
        return ""

    def _stats(self, info: JointInformation, solution: Solution, k: int) -> tuple[float, float]:
        """Value and standard error of column ``k`` of ``solution``."""
        sigma2 = solution.rss / max(info.samples - int(np.sum(solution.excited)), 1.0)
        infl = info.inflation[k] if math.isfinite(info.inflation[k]) else 1.0
        var = (sigma2 * info.w2 / info.w1 * solution.covariance_scaled[k, k]
               / solution.scale[k] ** 2 * infl)
        return float(solution.theta[k]), math.sqrt(var) if var >= 0.0 else math.nan

    def _parameter(self, name: str, value: float, variance: float, model_variance: float,
                   excited: bool, vif: float, cov_scaled: np.ndarray, k: int,
                   names: tuple[str, ...]) -> ParameterEstimate:
        s = self.settings
        se = math.sqrt(variance) if variance >= 0.0 else math.nan
        me = math.sqrt(model_variance)
        if not excited:
            return ParameterEstimate(name, math.nan, math.nan, math.nan, math.nan, False, False,
                                     "not identifiable: its regressor is zero (not excited)")
        identifiable = math.isfinite(vif) and vif <= s.max_variance_inflation
        reason = ""
        if not identifiable:
            reason = (f"not identifiable: variance inflation {vif:.3g} > "
                      f"{s.max_variance_inflation:g}, collinear with "
                      f"{most_correlated(cov_scaled, k, names)}")
        reason = reason or judge(name, value, se, s)
        half = Z95 * math.hypot(se, me)
        return ParameterEstimate(name, value, se, value - half, value + half, identifiable,
                                 not reason, reason, model_error=me)

    def _rest_position(self, theta: np.ndarray, cov: np.ndarray, model: np.ndarray,
                       params: Mapping[str, ParameterEstimate]) -> ParameterEstimate:
        """q_0 = -c / K, its variance and model error by the delta method."""
        k, c = theta[2], theta[3]
        stiffness = params["stiffness"]
        offset = params["offset"]
        carried = stiffness.combined_with + offset.combined_with
        if carried:
            return ParameterEstimate("rest_position", math.nan, math.nan, math.nan, math.nan,
                                     False, False, "not separately identifiable: stiffness "
                                     f"and offset carry {', '.join(carried)} (the loop uses "
                                     "K q + offset)")
        if not (stiffness.identifiable and offset.identifiable):
            return ParameterEstimate("rest_position", math.nan, math.nan, math.nan, math.nan,
                                     False, False, "not identifiable: stiffness or offset is not")
        if not (stiffness.value - Z95 * stiffness.standard_error > 0.0):
            return ParameterEstimate("rest_position", math.nan, math.nan, math.nan, math.nan,
                                     False, False, "not identifiable: no significant stiffness "
                                     "to define a rest position")
        q0 = -c / k
        grad = np.array([c / k ** 2, -1.0 / k])
        sub = cov[np.ix_([2, 3], [2, 3])]
        var = float(grad @ sub @ grad)
        se = math.sqrt(var) if var >= 0.0 else math.nan
        me = math.sqrt(max(float(grad @ model[np.ix_([2, 3], [2, 3])] @ grad), 0.0))
        reason = judge("rest_position", q0, se, self.settings)
        half = Z95 * math.hypot(se, me)
        return ParameterEstimate("rest_position", q0, se, q0 - half, q0 + half, True,
                                 not reason, reason, model_error=me)

    def _reflex_grid(self, info: JointInformation, best: int,
                     variance_scale: float) -> dict[str, ParameterEstimate]:
        """v_th and tau_r with intervals from the residual's profile: the grid points within
        chi^2_1(0.95) = 3.84 (scaled residual variance) of the least residual."""
        rss = info.grid_rss().reshape(len(self.delays), self.thresholds.shape[0])
        di, ti = divmod(best, self.thresholds.shape[0])
        limit = rss[di, ti] + 3.84 * variance_scale
        th_in = self.thresholds[rss[di] <= limit]
        delays = np.asarray(self.delays, dtype=float) * self.settings.period
        de_in = delays[rss[:, ti] <= limit]
        out = {}
        for name, value, inside, grid in (("reflex_threshold", self.thresholds[ti], th_in,
                                           self.thresholds),
                                          ("reflex_delay", delays[di], de_in, delays)):
            low, high = float(np.min(inside)), float(np.max(inside))
            at_edge = low <= grid[0] or high >= grid[-1]
            reason = ("its interval reaches the grid's edge (not determined)"
                      if at_edge and grid.shape[0] > 1 else "")
            out[name] = ParameterEstimate(name, float(value), (high - low) / (2 * Z95), low,
                                          high, not reason, not reason, reason)
        return out
