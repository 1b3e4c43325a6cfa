"""Mamdani fuzzy inference: piecewise-linear sets, rule-base files, a compiled evaluator.

``load_rulebase("paper")`` (or ``"default"``, or a path to a TOML file) returns a ``RuleBase`` with
``evaluate({name: array})`` (batch), ``evaluate_one(**floats)`` (control loop) and
``explain(**floats)`` (which rules fired). The file format is documented in docs/fuzzy.md.
"""

from rover_ctl.fuzzy.loader import load_rulebase, parse_rulebase, shipped
from rover_ctl.fuzzy.membership import FuzzySet, Variable
from rover_ctl.fuzzy.rulebase import Rule, RuleBase, RuleBaseError

__all__ = ["FuzzySet", "Rule", "RuleBase", "RuleBaseError", "Variable", "load_rulebase", "parse_rulebase", "shipped"]
