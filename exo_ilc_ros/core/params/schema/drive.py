"""The keys of a musculoskeletal person's neural drive (core/person/neural_drive.py): tone, the
stretch reflex per MAS grade or custom, voluntary activation and fatigue, each with its
source."""

from __future__ import annotations

from typing import Any

from .parameter import PLANT, Kind, Parameter
from .rules import MAS_GRADES, _fraction_rule


def drive_parameters() -> list[Parameter]:
    """A musculoskeletal person's neural drive (core/person/neural_drive.py), plant_simulator
    section; a grade's preset or the custom values (0: off)."""
    def p(name: str, text: str, **rules: Any) -> Parameter:
        return Parameter(f"person.drive.{name}", PLANT, Kind.DOUBLE, text, minimum=0.0, **rules)

    return [
        Parameter("person.drive.mas_grade", PLANT, Kind.STRING, "custom (the values below) or "
                  "a Modified Ashworth grade 0, 1, 1+, 2, 3 (Bohannon and Smith 1987): its "
                  "preset (neural_drive.py MAS_DRIVE_PRESETS, calibrated by exo-ilc "
                  "stretch-test) replaces tone, thresholds, gains and reflex_max",
                  choices=MAS_GRADES),
        p("tone", "baseline excitation of every muscle (share of full activation): resting "
          "muscle tone", extra_rule=_fraction_rule),
        p("length_threshold", "L_th: normalised fibre length (optimal fibre lengths, MuJoCo's "
          "force-length normalisation) above which a spastic muscle's stretch reflex fires "
          "(the motoneuron threshold of Feng and Mak 2002, Koo and Mak 2006; lower in "
          "spasticity)"),
        p("velocity_threshold", "V_th: lengthening velocity (optimal fibre lengths/s) above "
          "which the reflex's velocity term adds (the dynamic threshold, Feng and Mak 2002)"),
        p("length_gain", "g_l: reflex excitation per optimal length beyond L_th (spindle "
          "static gain, the most sensitive parameter of Koo and Mak 2006); 0: none"),
        p("velocity_gain", "g_v: reflex excitation per optimal length beyond L_th per optimal "
          "length/s beyond V_th (spindle dynamic gain; fibre length and velocity feedback: "
          "SpasticMyoElbow's best model of spastic resistance); 0: none"),
        p("reflex_max", "ceiling of the reflex excitation (share of full activation); 0: no "
          "reflex", extra_rule=_fraction_rule),
        p("reflex_delay", "delay from a muscle's length and velocity to its reflex "
          "excitation (s, rounded to simulation steps; SpasticMyoElbow 0.1 s)"),
        Parameter("person.drive.spastic_muscles", PLANT, Kind.STRING_ARRAY, "the muscles with "
                  "the stretch reflex, by the model's actuator names (those the model has; "
                  "the others get the tone only): the elbow flexors of post-stroke "
                  "spasticity"),
        p("voluntary_gain", "g_vol: the person's own excitation per optimal length/s of the "
          "shortening the intended movement asks of a muscle (its agonists help); 0: a "
          "passive person"),
        p("fatigue_rate", "f of dF/dt = f u - r F, F the fatigued share of a muscle's motor "
          "units, u its excitation, capacity 1 - F (Xia and Frey-Law 2008; elbow f = "
          "0.00912/s, Frey-Law et al. 2012, J Biomech 45:1803); 0: no fatigue"),
        p("recovery_rate", "r of the fatigue model: recovery of fatigued motor units (1/s; "
          "elbow 0.00094/s, Frey-Law et al. 2012)"),
    ]
