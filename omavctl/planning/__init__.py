"""Planning informative next flights (``omavctl plan``)."""

from omavctl.planning.planner import PlanResult, PlanSettings, plan

__all__ = ["PlanResult", "PlanSettings", "plan"]
