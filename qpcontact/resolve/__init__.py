"""resolve wing."""

from .resolve import Result, resolve, solve_system
from .validation import Agreement, compare_with_linear, reference_solution

__all__ = ["Agreement", "Result", "compare_with_linear", "reference_solution", "resolve", "solve_system"]
