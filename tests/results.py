"""The engine's typed result as its JSON document, for tests written against the document's keys.

`owcsim.engine.run.simulate.simulate` returns schemas.results.SimulationResultPublic; these wrappers
dump it the way result.json and the service write it (NaN and inf as null), so a test reads
`doc["links"][0]["dc_gain"]` as a user of the files would.
"""

from __future__ import annotations

import json

from owcsim.engine.run.simulate import simulate as _simulate
from owcsim.engine.run.simulate import simulate_two_sided as _two_sided


def simulate_document(*args, **kwargs) -> dict:
    return json.loads(_simulate(*args, **kwargs).model_dump_json())


def simulate_two_sided_document(*args, **kwargs) -> dict:
    return json.loads(_two_sided(*args, **kwargs).model_dump_json())
