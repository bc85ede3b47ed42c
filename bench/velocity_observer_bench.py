"""The velocity the feedback uses against MAS 3's delayed reflex (issue 33,
``control.velocity_observer``): the numbers of docs/patient-aware.md's *The encoder's velocity*.

Run with ``.venv/bin/python -m bench.velocity_observer_bench [--poles] [--patients 96 288 ...]
[--trials 25]``.

``--poles``: a linear model of one joint at 100 Hz (computed torque's double integrator with
the patient's stiffness and damping integrated over the period, MAS 3's reflex on the true
velocity 10 periods ago held over the period, PD on the velocity fed back: the true one, the
14-bit encoder's backward difference low-passed over 10 ms, or the observer of
core/loop/observer.py), its largest pole's radius and frequency per joint inertia.

``--patients``: seed 0's patients of ``exo-ilc certify --config config/patient_aware.yaml``
run in-process as the certificate runs them, with the observer (patient_aware.yaml's) and
without it (``control.velocity_observer: 1``); per patient the trial-25 worst true max |e|, the
first trial within the bound and the settled trial. Prints; asserts nothing.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.linalg import expm

from exo_ilc_ros.core.loop.observer import observer_gains

PERIOD = 0.01
FILTER_ALPHA = PERIOD / (0.01 + PERIOD)  # the encoder velocity's 10 ms low-pass
MAS3 = (8.0, 0.8, 2.0)  # the preset's stiffness, damping, reflex gain (core/loop/patient.py)


def pole(kp: float, kd: float, inertia: float, velocity: str, stiffness: float = 11.2,
         damping: float = 0.98, reflex: float = MAS3[2], delay: int = 10) -> tuple[float, float]:
    """(radius, Hz) of the largest pole of the joint's loop with the reflex active; velocity
    'true', 'encoder' or 'observer' (deadbeat)."""
    augmented = np.zeros((3, 3))
    augmented[0, 1] = 1.0
    augmented[1] = [-stiffness / inertia, -damping / inertia, 1.0]
    exact = expm(augmented * PERIOD)
    a_d, b_d = exact[:2, :2], exact[:2, 2]
    gains = observer_gains(np.zeros(1), np.ones(1, dtype=bool), PERIOD)[:, 0]
    n = 2 + delay + 2 + 4  # q, qdot, qdot history, last measured q, filtered v, observer, u

    def step(x: np.ndarray) -> np.ndarray:
        q, v = x[0], x[1]
        hist, last_q, filtered = x[2:2 + delay], x[2 + delay], x[3 + delay]
        q_hat, v_hat, d_hat, u_prev = x[4 + delay:8 + delay]
        raw = (q - last_q) / PERIOD
        measured = filtered + FILTER_ALPHA * (raw - filtered)
        acceleration = u_prev + d_hat
        predicted = q_hat + PERIOD * v_hat + 0.5 * PERIOD ** 2 * acceleration
        residual = q - predicted
        q_hat = predicted + gains[0] * residual
        v_hat = v_hat + PERIOD * acceleration + gains[1] * residual
        d_hat = d_hat + gains[2] * residual
        fed = {"true": v, "encoder": measured, "observer": v_hat}[velocity]
        u = -kp * q - kd * fed
        drive = u - reflex / inertia * hist[-1]
        out = np.zeros(n)
        out[:2] = a_d @ [q, v] + b_d * drive
        out[2] = v
        out[3:2 + delay] = hist[:-1]
        out[2 + delay], out[3 + delay] = q, measured
        out[4 + delay:8 + delay] = q_hat, v_hat, d_hat, u
        return out

    matrix = np.column_stack([step(e) for e in np.eye(n)])
    poles = np.linalg.eigvals(matrix)
    i = int(np.argmax(np.abs(poles)))
    return float(abs(poles[i])), float(abs(np.angle(poles[i])) / (2 * np.pi * PERIOD))


def print_poles() -> None:
    """The paper arm's elbow under the floors (1600 / 80) at its lightest inertia and
    heavier, and the shoulder flexion (272 / 30)."""
    for name, kp, kd, inertias in (("elbow 1600/80", 1600.0, 80.0, (0.011, 0.02, 0.041)),
                                   ("shoulder flexion 272/30", 272.0, 30.0, (0.066,))):
        for inertia in inertias:
            row = "  ".join(f"{v} {pole(kp, kd, inertia, v)[0]:.4f} "
                            f"({pole(kp, kd, inertia, v)[1]:.1f} Hz)"
                            for v in ("encoder", "observer", "true"))
            print(f"{name:24s} I {inertia:.3f}: {row}")


def run_patients(indices: list[int], trials: int) -> None:
    """Each patient with and without the observer (module docstring)."""
    from exo_ilc_ros.core.params.config import config_dir, load_config
    from exo_ilc_ros.core.population.certificate import (
        feedforward_limit,
        patient_cell,
        patient_config,
        patient_outcome,
    )
    from exo_ilc_ros.core.population.distributions import PopulationSpec, draw_patient
    from exo_ilc_ros.core.programs.study import run_cell
    base = load_config(None, overlays=[config_dir() / "patient_aware.yaml"])
    for index in indices:
        patient = draw_patient(base, PopulationSpec(), 0, index)
        cells = []
        for label, extra in (("observer", {}), ("measured", {"control.velocity_observer": 1.0})):
            start = time.perf_counter()
            config = patient_config(base, patient, trials, extra)
            result = run_cell(patient_cell("patient_aware", config, patient))
            outcome = patient_outcome(index, result, trials, feedforward_limit(config.values))
            cells.append(f"{label}: {outcome.final_error:.3e} rad, first {outcome.first}, "
                         f"settled {outcome.settled}, aborts {outcome.aborts} "
                         f"({time.perf_counter() - start:.0f} s)")
        print(f"patient {index} (MAS {patient.mas_grade}): " + "; ".join(cells), flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--poles", action="store_true")
    parser.add_argument("--patients", type=int, nargs="*", default=[])
    parser.add_argument("--trials", type=int, default=25)
    args = parser.parse_args()
    if args.poles:
        print_poles()
    if args.patients:
        run_patients(args.patients, args.trials)


if __name__ == "__main__":
    main()
