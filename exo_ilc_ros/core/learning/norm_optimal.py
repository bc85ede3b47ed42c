"""Norm-optimal ILC (Amann, Owens and Rogers) over the lifted model of the sampled closed loop.

Each trial's update minimises, over the next trial's feed-forward u (all joints, all N+1
samples, stacked sample by sample),

    J(u) = ||e_k+1||^2_We + ||u - u_ff,k||^2_Wd + ||u||^2_Wu,                           (NO1)

with the next error predicted by the lifted model e_k+1 = e_k - G (u - u_ff,k): G maps a change
of the feed-forward to the change of the position over one trial from x(0) = x_d(0) (the trial's
edges included exactly, the last sample's feed-forward is never applied), and We, Wd, Wu are
the per-joint weights ``norm_optimal.weight_error``, ``weight_input_change`` and
``weight_input_size``. Its minimiser is

    u_ff,k+1 = u_ff,k + H^-1 (G^T We e_k - Wu u_ff,k),   H = G^T We G + Wd + Wu,
             = Phi u_ff,k + L e_k,   L = H^-1 G^T We,   Phi = I - H^-1 Wu,              (NO2)

The constrained update (``norm_optimal.constrained``) minimises the same J subject to

    |tau_k+1| <= (1 - margin) control.effort_limit,   |u| <= feedforward_limit (where > 0),  (NO3)

tau_k+1 = tau_k + a_N(q_k) (u_k+1 - u_k) + J_k (x_k+1 - x_k) the computed torque of the next trial
predicted from this one's (u the whole input, feed-forward plus PD feedback, J_k = d tau / d x at
fixed u, x_k+1 - x_k from the model; margin = ``norm_optimal.effort_margin``), as a sparse QP in
the states of the model (:func:`solve_constrained`, Clarabel), instead of clipping the result
after the fact.

The model (``norm_optimal.model_kind``) is the closed loop the computed torque leaves when the
plant's masses are (1 + delta_m) times the nominal ones, delta_m =
``norm_optimal.model_mass_uncertainty``:

    qdd = g u - (1 - g) a_N(q)^-1 c_N(q, qdot),   g = 1 / (1 + delta_m),                (NO4)

the effort held over each period T, u = u_ff + K_P e + K_D e_dot.

* ``per_joint``: the second term's variation is neglected: per joint a ZOH double integrator of
  gain g under PD, the construction of :mod:`.convergence` (``analyze-loop``); G is block diagonal.
* ``linearised``: (NO4) linearised along the reference, the second term's Jacobians included
  (the gravity stiffness and velocity terms the mass error leaves): coupled and time-varying.

G, L and Phi depend only on the configuration (model, gains, period, reference, weights): they
are computed once and cached (:func:`learning_matrices`), so an update is one matrix-vector
product (milliseconds). The law itself (:class:`NormOptimalLaw`) uses the same minimiser without
them: the Riccati gains of :mod:`exo_ilc_ros.core.learning.norm_optimal_recursive`, cached the
same way (:func:`recursive_matrices`), memory linear in the samples; G, L and Phi remain for the
robustness check (``analyze-loop``) and as the tests' oracle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..arm.build import build_arm
from ..errors import SafetyError
from ..loop.record import TrialRecord
from ..params.config import Config
from ..reference.trajectory import SampledReference
from .laws import FeedforwardUpdate, InitialFeedforward, _initial
from .norm_optimal_model import PatientLinearisation, RecursiveMatrices, recursive_matrices
from .norm_optimal_qp import Constraints, constraint_notes, solve_constrained_recursive


@dataclass(frozen=True, eq=False)
class NormOptimalLaw:
    """Norm-optimal ILC, (NO2) (or (NO3) with ``constraints``): the feed-forward of the next
    trial minimises the weighted next error, input change and input size over the lifted model.
    Learns from the previous feed-forward (not the whole input: the model already holds the PD
    part), whatever ``memory`` says."""

    matrices: RecursiveMatrices
    constraints: Constraints | None = None
    initial: InitialFeedforward = InitialFeedforward.ZERO

    @classmethod
    def from_config(cls, config: Config, patient: PatientLinearisation | None = None
                    ) -> NormOptimalLaw:
        """The config's weights and model (matrices from the cache; about the identified
        ``patient`` when given), its limits when ``norm_optimal.constrained``."""
        constraints = None
        if config["norm_optimal.constrained"]:
            ff = np.asarray(config["feedforward_limit"], dtype=float)
            constraints = Constraints(np.asarray(config["control.effort_limit"], dtype=float),
                                      np.where(ff > 0.0, ff, np.inf),
                                      build_arm(config).kernel_args,
                                      float(config["norm_optimal.effort_margin"]))
        return cls(recursive_matrices(config, patient), constraints,
                   InitialFeedforward(config["initial_feedforward"]))

    def initial_feedforward(self, reference: SampledReference) -> np.ndarray:
        """Zero, or q_ddot_d, per the ``initial`` option."""
        return _initial(reference, self.initial)

    def update(self, record: TrialRecord) -> FeedforwardUpdate:
        """(NO2): u_ff,k+1 = Phi u_ff,k + L e_k; with constraints the QP (NO3), and a note
        naming the constraints that were active."""
        shape = record.feedforward.shape
        model = self.matrices.model
        if shape[0] != model.samples or shape[1] != model.joints:
            raise SafetyError(f"trial {record.trial}: {shape[0]} samples, but the learning "
                              f"matrix was built for {self.matrices.model.samples}")
        if self.constraints is not None:
            step = solve_constrained_recursive(self.matrices, self.constraints, record)
            notes = constraint_notes(step)
            return FeedforwardUpdate(record.feedforward + step.change, None, notes)
        new = self.matrices.next_feedforward(record.feedforward.ravel(), record.error.ravel())
        return FeedforwardUpdate(new.reshape(shape), None)
