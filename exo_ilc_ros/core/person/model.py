"""The person's arm with muscles, from MyoSuite's models (the ``myo-sim`` package, Apache-2.0):
MyoArm's right arm, or the small elbow model, as a ``mujoco.MjSpec`` ready to be composed with
the exoskeleton (:mod:`.strapped`).

* ``myoarm``: ``myo_sim.build.compose.build_spec("myoarm_r")``, the right arm of MyoArm
  (derived from the MoBL-ARMS OpenSim model, Holzbaur, Murray & Delp, Ann Biomed Eng 33(6),
  2005) on MyoSuite's passive torso scaffold (``make_torso_passive``: the torso has no joint,
  so it is fixed to the world). The hand and the fingers are **pruned**: the wrist and finger
  joints and forearm rotation (``pro_sup_r``) are deleted, which welds the carpal, metacarpal
  and phalanx bodies to the radius (their mass stays on the forearm), and the wrist and finger
  muscles (MyoSuite's own list, ``myo_sim.build.hand.RIGHT_HAND_ACTUATORS``, which includes
  the pronators PT and PQ) are deleted with their tendons. Left: the shoulder girdle
  (clavicle, scapula, coupled to shoulder elevation by MyoArm's equality constraints), the
  glenohumeral joint (``elv_angle_r``, ``shoulder_elv_r``, ``shoulder_rot_r``) and the elbow
  (``elbow_flexion_r``), 16 degrees of freedom, with the shoulder and elbow muscles (DELT1-3,
  SUPSP, INFSP, SUBSC, TMIN, TMAJ, PECM1-3, LAT1-3, CORB, TRIlong/lat/med, ANC, SUP,
  BIClong/short, BRA, BRD: 24 muscles).
* ``myoelbow``: ``models/legacy/elbow/myoelbow_2dof6muscles.xml``, shoulder elevation and
  elbow flexion in one plane, six muscles (TRIlong/lat/med, BIClong/short, BRA; the long
  triceps head and the biceps span both joints). The decorative skeleton is removed.

Contacts are off in both (the person does not touch the exoskeleton or itself: a forearm can
pass through the torso). Joint limits are the model's own (anatomical ranges, soft limits).
``mujoco`` and ``myo_sim`` are imported only when a model is built.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass
from importlib import resources
from typing import Any, Protocol

import numpy as np

from ..errors import ModelError

MYOARM_PRUNED_JOINTS = ("pro_sup_r", "deviation_r", "flexion_r", "cmc_flexion", "cmc_abduction",
                        "mp_flexion_r", "ip_flexion_r", "mcp2_flexion_r", "mcp2_abduction_r",
                        "pm2_flexion_r", "md2_flexion_r", "mcp3_flexion_r", "mcp3_abduction_r",
                        "pm3_flexion_r", "md3_flexion", "mcp4_flexion_r", "mcp4_abduction_r",
                        "pm4_flexion", "md4_flexion_r", "mcp5_flexion_r", "mcp5_abduction_r",
                        "pm5_flexion_r", "md5_flexion_r")
"""MyoArm's joints deleted (forearm rotation, wrist, thumb, fingers): their bodies are welded
to their parents."""


@dataclass(frozen=True)
class PersonAnatomy:
    """Where a person model's parts are: the names :mod:`.strapped` straps to."""

    name: str
    """``myoarm`` or ``myoelbow``."""
    upper_arm: str
    """The humerus body (the upper-arm cuff's body)."""
    forearm: str
    """The forearm body (the forearm cuff's body)."""
    shoulder_elevation: str
    """The joint of shoulder elevation (the exoskeleton's shoulder is placed on it)."""
    elbow_flexion: str
    """The joint of elbow flexion (the exoskeleton's elbow is placed on it)."""
    rest: tuple[tuple[str, float], ...] = ()
    """Joint angles (rad) of the person's rest pose, where the exoskeleton is strapped on;
    every other joint at 0 (MyoArm: the plane of elevation turned to 1.5 rad, so that
    shoulder elevation lifts the arm forwards, the exoskeleton's flexion; at zero elevation
    the plane does not move the arm)."""


class MuscleDrive(Protocol):
    """The hook that drives the person's muscles: called at every MuJoCo step with the
    step's fresh kinematics (``data.actuator_length``, ``data.actuator_velocity``, the
    muscles' fibre state; after ``mj_step1``), it writes each muscle's control (excitation,
    0..1) in the order of :func:`muscle_names` into ``controls``. ``reset`` is called when a
    trial begins (a reflex clears its delay lines there). The neural drive of
    :mod:`.neural_drive` (tone, stretch reflex) is one; None: passive muscles (zero
    excitation)."""

    def reset(self, model: Any, data: Any) -> None:
        """A trial begins at the state in ``data``."""

    def __call__(self, model: Any, data: Any, controls: np.ndarray) -> None:
        """Write the muscles' controls for the next step into ``controls``."""


ANATOMY = {
    "myoarm": PersonAnatomy("myoarm", "humerus_r", "ulna_r", "shoulder_elv_r",
                            "elbow_flexion_r", (("elv_angle_r", 1.5),)),
    "myoelbow": PersonAnatomy("myoelbow", "r_humerus", "r_ulna_radius_hand", "r_shoulder_elev",
                              "r_elbow_flex"),
}
"""The person models this package builds."""

PERSON_MODELS = tuple(ANATOMY)


def _myoarm_spec() -> Any:
    import warnings

    from myo_sim.build import compose
    from myo_sim.build.hand import RIGHT_HAND_ACTUATORS

    with warnings.catch_warnings():  # myo_sim attaches with an empty prefix (a notice only)
        warnings.simplefilter("ignore", UserWarning)
        spec = compose.build_spec("myoarm_r")
    tendons = set()
    for actuator in list(spec.actuators):
        if actuator.name in RIGHT_HAND_ACTUATORS:
            tendons.add(actuator.target)
            spec.delete(actuator)
    for tendon in list(spec.tendons):
        if tendon.name in tendons:
            spec.delete(tendon)
    drop_unused_sites(spec)
    for name in MYOARM_PRUNED_JOINTS:
        joint = spec.joint(name)
        if joint is None:
            raise ModelError(f"MyoArm has no joint {name!r} to prune (myo-sim changed?)")
        spec.delete(joint)
    return spec


def drop_unused_sites(spec: Any) -> int:
    """Delete the sites no tendon passes through (MyoArm keeps ~1000 marker and hand sites
    whose poses MuJoCo computes at every step: a fifth of a step's cost), and the contact
    pairs and exclusions (contacts are off). Returns how many sites went."""
    used: set[str] = set()
    for tendon in spec.tendons:
        for i in range(len(tendon.path)):
            wrap = tendon.path[i]
            for target in (wrap.target, wrap.sidesite):
                if target is None:
                    continue
                used.add(target if isinstance(target, str) else target.name)
    dropped = 0
    for site in list(spec.sites):
        if site.name not in used:
            spec.delete(site)
            dropped += 1
    for element in list(spec.pairs) + list(spec.excludes):
        spec.delete(element)
    return dropped


def _myoelbow_spec() -> Any:
    import mujoco

    path = resources.files("myo_sim") / "models" / "legacy" / "elbow" / \
        "myoelbow_2dof6muscles.xml"
    spec = mujoco.MjSpec.from_file(str(path))
    decor = spec.body("body_decor")
    if decor is not None:
        spec.delete(decor)
    return spec


_BUILT: dict[str, Any] = {}
"""The pruned specs built in this process (composing MyoArm costs seconds: myo-sim and the
pruning delete hundreds of elements one by one)."""


def person_spec(name: str) -> Any:
    """The uncompiled ``mujoco.MjSpec`` of person model ``name`` (module docstring), contacts
    off: a copy of the one built once per process, free to change. ModelError for a name that
    is not one of :data:`PERSON_MODELS`."""
    import mujoco

    if name not in ANATOMY:
        raise ModelError(f"no person model {name!r}; one of {', '.join(PERSON_MODELS)}")
    if name not in _BUILT:
        spec = _myoarm_spec() if name == "myoarm" else _myoelbow_spec()
        spec.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
        spec.modelname = f"person_{name}"
        _BUILT[name] = spec
    return _BUILT[name].copy()


def muscle_names(model: Any) -> list[str]:
    """The names of a compiled model's muscle actuators, in actuator order."""
    import mujoco

    return [model.actuator(i).name for i in range(model.nu)
            if model.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE]


def rest_pose(model: Any, anatomy: PersonAnatomy) -> np.ndarray:
    """qpos of the person at rest: :attr:`PersonAnatomy.rest`, every other joint at 0 and
    joints coupled by a joint equality (MyoArm's shoulder girdle) at their coupled value."""
    import mujoco

    qpos = np.array(model.qpos0)
    for name, value in anatomy.rest:
        qpos[model.jnt_qposadr[model.joint(name).id]] = value
    for i in range(model.neq):
        if model.eq_type[i] != mujoco.mjtEq.mjEQ_JOINT:
            continue
        a = model.jnt_qposadr[model.eq_obj1id[i]]
        x = 0.0
        if model.eq_obj2id[i] >= 0:
            b = model.jnt_qposadr[model.eq_obj2id[i]]
            x = qpos[b] - model.qpos0[b]
        c = model.eq_data[i]
        qpos[a] = model.qpos0[a] + c[0] + c[1] * x + c[2] * x ** 2 + c[3] * x ** 3 + c[4] * x ** 4
    return qpos


def compile_quietly(spec: Any) -> Any:
    """``spec.compile()`` without MuJoCo's notice that MyoArm's torso was attached with an
    empty prefix (myo-sim composes it so; nothing is wrong)."""
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Attaching a spec with an empty prefix")
        return spec.compile()
