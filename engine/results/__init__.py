"""Result documents and link figures built from the tallies."""
