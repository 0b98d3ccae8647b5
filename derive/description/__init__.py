"""Stage 1, the robot description: models.yaml, DH tables and URDF -> a validated, frozen :class:`~derive.description.robot.Robot`. No CAS here."""
