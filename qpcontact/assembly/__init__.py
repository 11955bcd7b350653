"""assembly wing."""
