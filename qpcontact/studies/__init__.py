"""studies wing."""
