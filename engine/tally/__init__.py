"""Tallies of path contributions and the statistics of their estimates."""
