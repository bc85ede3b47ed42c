"""The project's own learning laws by short name (``exo-ilc study --laws``): light, so the
command line can name them without loading the experiment."""

from __future__ import annotations

from typing import Any

SHIPPED_LAWS: dict[str, tuple[str | None, dict[str, Any]]] = {
    "sign": (None, {}),
    "tuned": ("tuned.yaml", {}),
    "linear": (None, {"law": "linear"}),
    "robust": ("robust.yaml", {}),
    "norm_optimal": (None, {"law": "norm_optimal"}),
}
"""Short name -> (file of the shipped config directory, values): ``sign`` is the shipped default
(the paper's law), ``tuned`` its tuned schedules, ``linear`` and ``norm_optimal`` the shipped
config with that law (and its shipped gains or weights), ``robust`` the Q-filtered linear law."""
