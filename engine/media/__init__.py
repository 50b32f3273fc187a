"""Participating media (homogeneous, grid, particles/Mie) and their phase functions."""
