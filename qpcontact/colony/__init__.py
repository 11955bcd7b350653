"""colony wing."""
