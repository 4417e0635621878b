"""Vehicle identification from its own logs."""
