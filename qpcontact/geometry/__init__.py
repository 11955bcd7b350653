"""geometry wing."""
