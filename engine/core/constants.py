"""Physical constants and numerical knobs of the engine, each with its unit."""

#: Speed of light in vacuum (refractive index 1 everywhere) [m/s].
SPEED_OF_LIGHT = 299_792_458.0

#: Ray origin offset off a surface, as a fraction of the scene's extent [-].
#: Embree works in float32 on re-centred vertices: 1e-6 of the extent is ~10x the
#: float32 rounding of a hit point, and still 200x smaller than 1 mm in a 5 m room.
RAY_OFFSET_FACTOR = 1e-6

#: Largest extent of a scene (surfaces and devices) [m]. Embree's float32 and the offset above
#: scale with it: at 2 km the offset is 2 mm and a hit point rounds by ~0.1 mm, the most a
#: device of a few mm can bear. Larger scenes are refused, not traced imprecisely.
MAX_SCENE_EXTENT = 2000.0

#: Triangles whose area is below this fraction of extent^2 are dropped as degenerate.
DEGENERATE_AREA_FACTOR = 1e-14

#: Paths whose weight falls to exactly zero are retired; no other threshold biases results.
