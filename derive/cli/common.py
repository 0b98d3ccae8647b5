"""What every command module shares: reading the robots a command names."""

from __future__ import annotations

from derive.description.model import load_models
from derive.description.robot import ModelError


def robots_of(args) -> dict:
    """The robots of ``args.models`` (all, checked against ``args.robot`` when given)."""
    robots = load_models(args.models)
    if getattr(args, "robot", None):
        missing = [r for r in args.robot if r not in robots]
        if missing:
            raise ModelError(missing[0], "robots", f"no such robot in {args.models or 'models.yaml'} (known: {', '.join(robots)})")
    return robots
