"""The built scene: geometry, regions, intersection and line of sight."""
