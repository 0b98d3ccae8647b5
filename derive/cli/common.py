"""What every command module shares: reading the robots a command names."""

from __future__ import annotations

from derive.description.model import default_models_path, load_models
from derive.description.robot import ModelError


def robots_of(args) -> dict:
    """The robots of ``args.models`` (all, checked against ``args.robot`` when given)."""
    robots = load_models(args.models)
    if getattr(args, "robot", None):
        missing = [r for r in args.robot if r not in robots]
        if missing:
            source = args.models or default_models_path()
            raise ModelError(missing[0], "robots", f"no such robot in {source} (known: {', '.join(robots)})")
    return robots
