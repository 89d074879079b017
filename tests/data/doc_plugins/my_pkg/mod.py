"""A safety monitor written from docs/plugins.md: stop a robot while another robot or a person
is within radius_m of its estimate, or while it has no estimate."""

import math
from dataclasses import dataclass

from simlan_data.algorithms.safety.conditions import FREE, SafetyDecision


@dataclass(frozen=True)
class MyMonitorConfig:
    radius_m: float = 1.0


class MyMonitor:
    role = "safety"
    config_class = MyMonitorConfig

    def __init__(self, config, context):
        self.radius_m = config.radius_m
        self.robots = [r.namespace for r in context.robots if r.kind == "robot"]

    def step(self, world):
        out = {}
        for ns in self.robots:
            est = world.estimates.get(ns)
            if est is None or est.pose is None:
                out[ns] = SafetyDecision("stop", "no_estimate")
                continue
            x, y = est.pose[0], est.pose[1]
            near = [
                o
                for o, e in world.estimates.items()
                if o != ns and e.pose is not None and math.hypot(e.pose[0] - x, e.pose[1] - y) < self.radius_m
            ]
            near += [p.name for p in world.people if math.hypot(p.x_m - x, p.y_m - y) < self.radius_m]
            out[ns] = SafetyDecision("stop", "proximity", detail=",".join(map(str, near))) if near else FREE
        return out
