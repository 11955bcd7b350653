"""solvers wing."""
