"""Evaluation: the paper's experiments for every planner, a results database, tables and plots."""

from rayreach.evaluate.report import write_report
from rayreach.evaluate.runner import EvaluationConfig, evaluate, parse_experiments

__all__ = ["EvaluationConfig", "evaluate", "parse_experiments", "write_report"]
