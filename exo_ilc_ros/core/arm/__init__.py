"""The arm, eqs (1)-(7) by the Rodriguez approach: its model (truncated cones, or read from a
URDF), the compiled dynamics, the passive joint forces of eq (6), the URDF writer and reader,
forward kinematics, a person's segments (de Leva 1996), MuJoCo from the same URDF."""
