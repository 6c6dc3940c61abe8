"""Ready-made case studies as scenario files, and the scenario loader."""

from .loader import GENERATORS, Scenario, block_registry, builtin_scenarios, load_scenario

__all__ = ["Scenario", "load_scenario", "builtin_scenarios", "block_registry",
           "GENERATORS"]
