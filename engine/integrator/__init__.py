"""The one path-tracing kernel and its events (surface vertex, segment points, medium collision, roulette)."""
