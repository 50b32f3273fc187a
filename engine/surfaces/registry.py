"""The surface models a material can mix, by the `type` of their wire model (schemas/surfaces.py).

`SURFACE_MODELS` maps each surface `type` to its `Lobe` (lobes.py); a material (bsdf.Materials) holds one lobe of
each registered model per face and mixes them in this order: the BRDF and the density are the sums of the lobes'
terms in this order, and sampling picks a lobe by cumulative albedo shares in this order (the first one, the
diffuse `lambertian`, is the part every surface type may carry: its `diffuse_fraction` r_d). Adding a model is
its file (a `Lobe` subclass) and one line here; its wire model in schemas/surfaces.py gives the same `type`, a
`reflectance` rho, a `diffuse_fraction` r_d and the lobe's `parameters` (CONTRIBUTING.md, "Add a surface model").
"""

from __future__ import annotations

from owcsim.engine.surfaces.lobes import Lambert, Lobe, Mirror, Phong

__all__ = ["DIFFUSE", "SURFACE_MODELS"]

#: the model of a plain number (a Lambertian reflectance) and of every spec's diffuse part r_d rho
DIFFUSE = "lambertian"

SURFACE_MODELS: dict[str, type[Lobe]] = {
    DIFFUSE: Lambert,
    "phong": Phong,
    "mirror": Mirror,
}
