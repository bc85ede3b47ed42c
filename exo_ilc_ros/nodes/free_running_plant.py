"""free_running_plant: our own simulator (core/loop/plant.py's RK4) as any arm, without the reset
and start services (``protocol: homing``); the node is :class:`.mujoco_plant.FreeRunningPlant`."""

from __future__ import annotations

from .common import spin
from .mujoco_plant import FreeRunningPlant
from .plant_base import NAME

__all__ = ["NAME", "FreeRunningPlant", "main"]


def main(args: list[str] | None = None) -> int:
    """Entry point: ``ros2 run exo_ilc_ros free_running_plant``."""
    return spin(FreeRunningPlant, args)


if __name__ == "__main__":
    raise SystemExit(main())
