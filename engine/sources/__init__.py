"""Transmitters and receivers: emission patterns (Lambertian, IES/LDT), fields of view, filters."""
