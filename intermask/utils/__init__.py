"""Small helpers shared by the entry points (run records, logging)."""
