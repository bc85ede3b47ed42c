"""The person's neural drive: what the spinal cord sends each muscle of a MuJoCo musculoskeletal
model (MyoArm, the MyoSuite elbow), one controller step per ``mj_step``.

Per muscle i, at simulation step k (:meth:`NeuralDrive.step`, the law in
:func:`reflex_excitation`):

    u_i(k) = min(c_i(k), tone + r_i(k) + v_i(k)),  clipped to the actuator's ctrlrange,

* **tone**: a baseline excitation of every muscle (resting muscle tone);
* **stretch reflex** (spastic muscles only), from the muscle's normalised fibre length L_i
  (optimal fibre lengths L0) and lengthening velocity V_i (L0/s), both read D = round(delay /
  timestep) steps earlier from a ring buffer:

      r_i = min(R, max(0, L_i(k - D) - L_th) (g_l + g_v max(0, V_i(k - D) - V_th)))

  the spindle's static (length) and dynamic (velocity) response above the motoneuron pool's
  thresholds (Feng and Mak 2002; Koo and Mak 2006), the feedback on fibre length and velocity
  that SpasticMyoElbow found to reproduce spastic elbow resistance best (delay 0.1 s). The
  velocity term's gain grows with the stretch beyond the length threshold (SpasticMyoElbow adds
  the two): the reflex torque then starts at a threshold angle set by L_th and rises with a
  torque-angle slope that grows with the stretch velocity, as McPherson et al. 2018 measured;
  an added velocity term is a step at the stretch's start whose slope does not grow;
* **voluntary activation toward the movement** (optional): v_i = g_vol max(0, -s_i) with s_i
  the fibre velocity the intended joint velocities would give the muscle (moment arms times
  :attr:`NeuralDrive.intent`): the muscles that the intended movement shortens help it;
* **fatigue** (optional): c_i = 1 - F_i, the fatigued share of the muscle's motor units,
  dF_i/dt = f u_i - r F_i (Xia and Frey-Law 2008's three-compartment model with the active
  share taken as the excitation; elbow rates of Frey-Law et al. 2012).

MuJoCo's muscles are rigid-tendon (their length is the musculotendon path), so the fibre length
and velocity are MuJoCo's own normalisation of the actuator's length
(``L = range_0 + (l - lengthrange_0) / L0``, ``L0 = (lengthrange_1 - lengthrange_0) /
(range_1 - range_0)``): the normalised length its force-length curve uses. The muscle's
activation dynamics (MuJoCo's, 10 / 40 ms) then turn the excitation written to ``data.ctrl``
into force.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numba import njit

from .. import _numba_cache  # noqa: F401  (sets numba's cache directory before any kernel)
from ..errors import ConfigError
from ..params.config import Config

DRIVE_PREFIX = "person.drive."
REFLEX_KEYS = ("tone", "length_threshold", "velocity_threshold", "length_gain", "velocity_gain",
               "reflex_max")
"""The keys a MAS grade's preset sets (:data:`MAS_DRIVE_PRESETS`)."""


@dataclass(frozen=True)
class DriveSettings:
    """The neural drive's parameters (the ``person.drive.*`` keys; units as there)."""

    tone: float = 0.0
    """Baseline excitation of every muscle (share of full activation)."""
    length_threshold: float = 1.0
    """L_th: normalised fibre length (optimal lengths) above which the reflex fires."""
    velocity_threshold: float = 0.0
    """V_th: lengthening velocity (optimal lengths per s) above which the velocity term adds."""
    length_gain: float = 0.0
    """g_l: excitation per optimal length beyond L_th (the static response)."""
    velocity_gain: float = 0.0
    """g_v: excitation per optimal length beyond L_th per optimal length per s beyond V_th
    (the dynamic response)."""
    reflex_max: float = 1.0
    """R: ceiling of the reflex excitation."""
    delay: float = 0.1
    """Reflex delay (s; rounded to simulation steps)."""
    spastic_muscles: tuple[str, ...] = ()
    """The muscles with the stretch reflex (the model's others get the tone only)."""
    voluntary_gain: float = 0.0
    """g_vol: excitation per optimal length per s of intended shortening; 0: a passive person."""
    fatigue_rate: float = 0.0
    """f: rate at which active motor units fatigue (1/s); 0: no fatigue."""
    recovery_rate: float = 0.0
    """r: rate at which fatigued motor units recover (1/s)."""

    @property
    def has_reflex(self) -> bool:
        """Any stretch reflex at all (a gain and a ceiling above 0)."""
        return self.reflex_max > 0.0 and (self.length_gain > 0.0 or self.velocity_gain > 0.0)


MAS_DRIVE_PRESETS: dict[str, DriveSettings] = {
    "0": DriveSettings(tone=0.0, length_threshold=2.0, velocity_threshold=10.0,
                       length_gain=0.0, velocity_gain=0.0, reflex_max=0.0),
    "1": DriveSettings(tone=0.01, length_threshold=1.0, velocity_threshold=0.2,
                       length_gain=0.025, velocity_gain=0.3, reflex_max=0.1),
    "1+": DriveSettings(tone=0.015, length_threshold=0.92, velocity_threshold=0.15,
                        length_gain=0.04, velocity_gain=0.5, reflex_max=0.2),
    "2": DriveSettings(tone=0.02, length_threshold=0.84, velocity_threshold=0.1,
                       length_gain=0.06, velocity_gain=0.75, reflex_max=0.4),
    "3": DriveSettings(tone=0.03, length_threshold=0.75, velocity_threshold=0.05,
                       length_gain=0.1, velocity_gain=1.2, reflex_max=0.8),
}
"""MAS grade -> tone, thresholds, gains and ceiling of the spastic muscles' reflex (the other
settings, delay and spastic muscles, from the config). Derived, not fitted (see
docs/stretch-test.md): the gains rise and the thresholds fall from grade to grade as Feng and
Mak 2002 and Koo and Mak 2006 found spastic subjects' reflex gain higher and their static and
dynamic thresholds lower; the length threshold puts the catch where the Modified Ashworth
grades describe it (Bohannon and Smith 1987: grade 1 at the end of the range, 3 through it);
set on the stretch test of the MyoSuite elbow so that grade 0 shows no reflex and the reflex
stiffness of grades 1-3 rises with stretch velocity as McPherson et al. 2018 measured. A table
fitted to one patient should replace them."""


def drive_settings(config: Config) -> DriveSettings:
    """The neural drive of a config: the MAS grade's preset (``person.drive.mas_grade``) or
    the ``custom`` values, with the delay, spastic muscles, voluntary and fatigue keys."""
    grade = str(config[DRIVE_PREFIX + "mas_grade"])
    common = DriveSettings(
        delay=float(config[DRIVE_PREFIX + "reflex_delay"]),
        spastic_muscles=tuple(config[DRIVE_PREFIX + "spastic_muscles"]),
        voluntary_gain=float(config[DRIVE_PREFIX + "voluntary_gain"]),
        fatigue_rate=float(config[DRIVE_PREFIX + "fatigue_rate"]),
        recovery_rate=float(config[DRIVE_PREFIX + "recovery_rate"]))
    if grade == "custom":
        values: dict[str, Any] = {name: float(config[DRIVE_PREFIX + name])
                                  for name in REFLEX_KEYS}
        return replace(common, **values)
    if grade not in MAS_DRIVE_PRESETS:
        raise ConfigError(DRIVE_PREFIX + "mas_grade", f"unknown grade {grade!r}; use custom or "
                          f"one of {', '.join(MAS_DRIVE_PRESETS)}")
    return with_preset(common, grade)


def with_preset(settings: DriveSettings, grade: str) -> DriveSettings:
    """``settings`` with a MAS grade's tone, thresholds, gains and ceiling."""
    preset = MAS_DRIVE_PRESETS[grade]
    values: dict[str, Any] = {name: getattr(preset, name) for name in REFLEX_KEYS}
    return replace(settings, **values)


def reflex_excitation(length: np.ndarray, velocity: np.ndarray,
                      settings: DriveSettings) -> np.ndarray:
    """The stretch reflex's excitation r = min(R, max(0, L - L_th) (g_l + g_v max(0, V - V_th)))
    of (already delayed) normalised fibre lengths L and lengthening velocities V (the module's
    law; Feng and Mak 2002, Koo and Mak 2006: spindle static and dynamic response above the
    motoneuron threshold)."""
    s = settings
    beyond = np.maximum(np.asarray(length, dtype=float) - s.length_threshold, 0.0)
    faster = np.maximum(np.asarray(velocity, dtype=float) - s.velocity_threshold, 0.0)
    return np.minimum(beyond * (s.length_gain + s.velocity_gain * faster), s.reflex_max)


@dataclass(frozen=True, eq=False)
class MuscleGeometry:
    """MuJoCo's normalisation of each driven muscle: L = offset + length * scale,
    V = velocity * scale (``scale = 1 / L0``)."""

    actuators: np.ndarray
    """Actuator ids of the muscles, in the drive's order."""
    names: tuple[str, ...]
    scale: np.ndarray
    offset: np.ndarray
    ctrl_low: np.ndarray
    ctrl_high: np.ndarray

    @classmethod
    def of(cls, model: Any) -> MuscleGeometry:
        """Every muscle actuator of a MuJoCo model (``mjDYN_MUSCLE``)."""
        import mujoco
        m = model  # mujoco.MjModel
        ids = np.flatnonzero(m.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE)
        if ids.size == 0:
            raise ConfigError(DRIVE_PREFIX + "spastic_muscles", "the person's model has no "
                              "muscle actuators (dyntype muscle)")
        gain = m.actuator_gainprm[ids]
        span = m.actuator_lengthrange[ids]
        optimal = (span[:, 1] - span[:, 0]) / np.maximum(gain[:, 1] - gain[:, 0], 1e-15)
        scale = 1.0 / optimal
        names = tuple(m.actuator(int(i)).name for i in ids)
        ctrl = m.actuator_ctrlrange[ids]
        limited = m.actuator_ctrllimited[ids].astype(bool)
        return cls(ids, names, scale, gain[:, 0] - span[:, 0] * scale,
                   np.where(limited, ctrl[:, 0], 0.0), np.where(limited, ctrl[:, 1], 1.0))


# Rows of the kernel's ``geometry`` array (per driven muscle):
_SCALE, _OFFSET, _LOW, _HIGH, _SPASTIC = range(5)
# Entries of the kernel's ``law`` array:
(_TONE, _L_TH, _V_TH, _G_L, _G_V, _R_MAX, _G_VOL, _FATIGUE, _RECOVERY, _DT,
 _DELAY) = range(11)
# Rows of the kernel's ``muscles`` array (per driven muscle):
_REFLEX, _EXCITATION, _FATIGUED, _INTENDED = range(4)


@njit(cache=True, error_model="numpy")
def drive_step_kernel(length: np.ndarray, velocity: np.ndarray, ctrl: np.ndarray,
                      actuators: np.ndarray, geometry: np.ndarray, history: np.ndarray,
                      step: int, law: np.ndarray, muscles: np.ndarray) -> None:
    """One step of :class:`NeuralDrive` (the module's law): record the driven muscles' normalised
    length and velocity in slot ``step % depth`` of ``history`` (2, depth, muscles; at step 0
    every slot), read them ``law[_DELAY]`` steps back, write the excitations to ``ctrl`` and the
    reflex, excitation and fatigue into ``muscles``."""
    depth = history.shape[1]
    delay = int(law[_DELAY])
    slot = step % depth
    past = (step - delay + depth) % depth  # before step D: a slot still holding step 0's
    for i in range(actuators.size):
        a = actuators[i]
        now_length = length[a] * geometry[_SCALE, i] + geometry[_OFFSET, i]
        now_velocity = velocity[a] * geometry[_SCALE, i]
        if step == 0:
            history[0, :, i] = now_length
            history[1, :, i] = now_velocity
        history[0, slot, i] = now_length
        history[1, slot, i] = now_velocity
        reflex = 0.0
        if geometry[_SPASTIC, i] > 0.0:
            beyond = max(history[0, past, i] - law[_L_TH], 0.0)
            faster = max(history[1, past, i] - law[_V_TH], 0.0)
            reflex = min(beyond * (law[_G_L] + law[_G_V] * faster), law[_R_MAX])
        drive = law[_TONE] + reflex + law[_G_VOL] * max(-muscles[_INTENDED, i], 0.0)
        if law[_FATIGUE] > 0.0:
            drive = min(drive, 1.0 - muscles[_FATIGUED, i])
        drive = min(max(drive, geometry[_LOW, i]), geometry[_HIGH, i])
        if law[_FATIGUE] > 0.0:
            muscles[_FATIGUED, i] += law[_DT] * (law[_FATIGUE] * drive
                                                 - law[_RECOVERY] * muscles[_FATIGUED, i])
        ctrl[a] = drive
        muscles[_REFLEX, i] = reflex
        muscles[_EXCITATION, i] = drive


class NeuralDrive:
    """The per-step controller of a musculoskeletal person: :meth:`step` reads the muscles'
    lengths and velocities from ``MjData`` and writes their excitations to ``data.ctrl``
    (call it before every ``mj_step``; one compiled kernel, :func:`drive_step_kernel`).
    :attr:`intent` (the intended joint velocity per dof) drives the voluntary activation;
    :meth:`reset` starts a new stretch or trial."""

    def __init__(self, model: Any, settings: DriveSettings,
                 timestep: float | None = None) -> None:
        self.settings = settings
        self.geometry = MuscleGeometry.of(model)
        self.model = model
        dt = float(timestep if timestep is not None else model.opt.timestep)
        self.timestep = dt
        self.delay_steps = steps_of(settings.delay, dt)
        names = self.geometry.names
        known = [name for name in settings.spastic_muscles if name in names]
        if settings.spastic_muscles and not known and settings.has_reflex:
            raise ConfigError(DRIVE_PREFIX + "spastic_muscles", f"none of "
                              f"{list(settings.spastic_muscles)} is a muscle of the person's "
                              f"model ({', '.join(names)})")
        self.spastic = np.array([name in settings.spastic_muscles for name in names])
        g = self.geometry
        self._geometry = np.vstack([g.scale, g.offset, g.ctrl_low, g.ctrl_high,
                                    self.spastic.astype(float)])
        s = settings
        self._law = np.array([s.tone, s.length_threshold, s.velocity_threshold, s.length_gain,
                              s.velocity_gain, s.reflex_max, s.voluntary_gain, s.fatigue_rate,
                              s.recovery_rate, dt, float(self.delay_steps)])
        self._history = np.zeros((2, self.delay_steps + 1, len(names)))
        self._muscles = np.zeros((4, len(names)))
        self._k = 0
        self._moment = np.zeros((model.nu, model.nv))
        self.intent: np.ndarray | None = None

    def reset(self, model: Any = None, data: Any = None) -> None:
        """Forget the delayed history and the fatigue (the history refills from the next step:
        until D steps have passed the reflex sees the first sample). ``model`` and ``data``
        are the :class:`~.model.MuscleDrive` hook's (a trial begins there; unused)."""
        self._k = 0
        self._muscles[:] = 0.0

    def __call__(self, model: Any, data: Any, controls: np.ndarray) -> None:
        """The :class:`~.model.MuscleDrive` hook of the strapped plant: one :meth:`step`, the
        muscles' excitations (actuator order, as :func:`.model.muscle_names`) into
        ``controls``."""
        controls[:] = self.step(data)

    def sense(self, data: Any) -> tuple[np.ndarray, np.ndarray]:
        """Normalised fibre length and lengthening velocity (L0/s) of the driven muscles now."""
        g = self.geometry
        length = data.actuator_length[g.actuators] * g.scale + g.offset
        velocity = data.actuator_velocity[g.actuators] * g.scale
        return length, velocity

    def step(self, data: Any) -> np.ndarray:
        """One controller step: sense, delay, excite; writes ``data.ctrl`` of the muscles and
        returns their excitations (a view, overwritten by the next step)."""
        if self.settings.voluntary_gain > 0.0 and self.intent is not None:
            self._muscles[_INTENDED] = self.intended_velocity(data)
        drive_step_kernel(data.actuator_length, data.actuator_velocity, data.ctrl,
                          self.geometry.actuators, self._geometry, self._history, self._k,
                          self._law, self._muscles)
        self._k += 1
        return self._muscles[_EXCITATION]

    @property
    def reflex(self) -> np.ndarray:
        """The reflex excitation of each driven muscle at the last step."""
        return self._muscles[_REFLEX]

    @property
    def excitation(self) -> np.ndarray:
        """The excitation written for each driven muscle at the last step."""
        return self._muscles[_EXCITATION]

    def intended_velocity(self, data: Any) -> np.ndarray:
        """The fibre velocity (L0/s) the intended joint velocities give each driven muscle:
        moment arms (d length / d q) times :attr:`intent`."""
        import mujoco
        mujoco.mju_sparse2dense(self._moment, data.actuator_moment, data.moment_rownnz,
                                data.moment_rowadr, data.moment_colind)
        g = self.geometry
        return (self._moment[g.actuators] @ np.asarray(self.intent)) * g.scale

    @property
    def fatigue(self) -> np.ndarray:
        """F_i: the fatigued share of each driven muscle's motor units."""
        return self._muscles[_FATIGUED].copy()


def drive_for(config: Config, model: Any) -> NeuralDrive | None:
    """The strapped plant's muscle drive of a config (a :data:`.experiment.DriveFactory`): the
    neural drive of ``person.drive.*`` on ``model``'s muscles, or None (passive muscles, as
    without the keys) when it has no tone, no reflex and no voluntary activation."""
    settings = drive_settings(config)
    if settings.tone == 0.0 and not settings.has_reflex and settings.voluntary_gain == 0.0:
        return None
    return NeuralDrive(model, settings)


def steps_of(delay: float, timestep: float) -> int:
    """Simulation steps of a reflex delay (rounded half up)."""
    return int(math.floor(delay / timestep + 0.5))
