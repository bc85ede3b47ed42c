"""Which parameters of the identification of the patient's joint forces
(:mod:`.identification`) a movement cannot separate, and why one was left out of the fit."""

from __future__ import annotations

import math

import numpy as np

from .identification_settings import IdentificationSettings


def inseparable_pairs(covariance_scaled: np.ndarray, names: tuple[str, ...],
                      max_correlation: float = 0.99) -> tuple[tuple[str, str, float], ...]:
    """The pairs of parameters the movement cannot separate: those whose estimates correlate
    by more than ``max_correlation`` in absolute value under ``covariance_scaled`` (the inverse
    of the column-scaled information matrix Phi^T Phi, one row per name). Each pair is
    (name_a, name_b, correlation), the strongest first. Only their combination is determined:
    e.g. friction F_c tanh(v / v_s) and the constant offset when the joint never reverses
    (tanh is then nearly constant, so F_c trades one for one against the offset K q_0).
    A parameter whose variance is not finite (not excited) is in no pair."""
    c = np.asarray(covariance_scaled, dtype=float)[:len(names), :len(names)]
    d = np.sqrt(np.abs(np.diag(c)))
    pairs = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if not (math.isfinite(d[a]) and math.isfinite(d[b]) and d[a] > 0.0 and d[b] > 0.0):
                continue
            corr = float(c[a, b] / (d[a] * d[b]))
            if math.isfinite(corr) and abs(corr) > max_correlation:
                pairs.append((names[a], names[b], corr))
    return tuple(sorted(pairs, key=lambda pair: -abs(pair[2])))


def inseparable_reason(name: str, kept: str, pairs: tuple[tuple[str, str, float], ...],
                        fastest: np.ndarray, s: IdentificationSettings) -> str:
    """Why ``name`` was left out of the fit: ``kept`` carries it."""
    r = next(r for keep, drop, r in pairs if drop == name)
    if math.isnan(r):
        return (f"not separately identifiable from {kept}: the joint never moved faster than "
                f"{s.reversal_speed:g} rad/s in both directions (fastest {fastest[0]:.3g} / "
                f"{fastest[1]:.3g}), so F_c sgn(qdot) is a constant of the movement; only "
                f"{kept} + F_c sgn(qdot) is determined, carried by {kept}")
    return (f"not separately identifiable from {kept} (correlation {r:.4f}): only their "
            f"combination is determined, carried by {kept}")


def most_correlated(cov_scaled: np.ndarray, k: int, names: tuple[str, ...]) -> str:
    """The parameter whose estimate correlates most with parameter ``k``'s."""
    c = cov_scaled
    d = np.sqrt(np.abs(np.diag(c)))
    with np.errstate(divide="ignore", invalid="ignore"):
        corr = c[k] / (d[k] * d)
    corr = np.where(np.isfinite(corr), np.abs(corr), -1.0)
    corr[k] = -1.0
    other = int(np.argmax(corr[:len(names)]))
    return f"{names[other]} (correlation {corr[other]:.3f})"
