"""Numerical helpers every part uses: constants, errors, input files, lazy imports, random and quasi-random sampling."""
