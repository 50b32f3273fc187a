"""Property-based fuzz of the HTTP API from its OpenAPI document (schemathesis): no answer is a 500,
and every answer matches the document (status codes, media types, headers, bodies, auth).

The app runs in-process (ASGI) with API keys on and its dispatcher running, under small
limits so that the jobs the fuzz manages to queue finish quickly. One check is left out:
`positive_data_acceptance` (a schema-valid request must be accepted): a scene has rules
JSON Schema cannot state (a device inside the room, `paths` or `target_rel_error` but not
both, the server's limits), so such documents get a located 422, the answer they should get
(and see `checks` for the scene body).

Not part of the default run (it is slower): `.ci/run` runs it, or
`scripts/test tests/server/fuzz_openapi.py`. FUZZ_EXAMPLES sets the examples per operation.
"""

import atexit
import os
import shutil
import sqlite3
import tempfile
import time
import warnings
from collections import Counter
from pathlib import Path

import pytest
import schemathesis
from hypothesis import HealthCheck, settings

from owcsim.server.app import create_app
from owcsim.server.settings import Settings

EXAMPLES = int(os.environ.get("FUZZ_EXAMPLES", "100"))
KEY = "fuzz-key"
SCENARIO_JOBS: Counter = Counter()  # final status of the jobs the stateful scenarios submitted

DB = Path(tempfile.mkdtemp(prefix="owcsim-fuzz-")) / "jobs.sqlite"
atexit.register(shutil.rmtree, DB.parent, ignore_errors=True)  # the store lives as long as the module's app
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    app = create_app(
        Settings(
            db=DB,
            api_keys=KEY,
            max_concurrent_jobs=1,
            max_queued_jobs=40,
            max_paths_per_job=200_000,
            max_wall_time_s=5,
            max_receivers=2000,
            max_body_bytes=256 * 1024,
        ),
        run_jobs=False,
    )
schema = schemathesis.openapi.from_asgi("/v1/openapi.json", app)


@schema.auth()
class ApiKey:
    def get(self, case, context):
        return KEY

    def set(self, case, data, context):
        case.headers = {**(case.headers or {}), "Authorization": f"Bearer {data}"}


@pytest.fixture(scope="module", autouse=True)
def dispatcher():
    # Started here: the ASGI transport may run the app's lifespan per call. That lifespan (run_jobs=False)
    # ends by closing the store, every thread's connection included, while this dispatcher's thread may be
    # writing through its own: a use after close in SQLite, which crashed the process once (CI). The store
    # closes once, after the dispatcher has stopped.
    store = app.state.store
    close, store.close = store.close, lambda *a, **k: None
    app.state.dispatcher.start()
    yield
    alive = app.state.dispatcher.alive
    app.state.dispatcher.stop()
    store.close = close
    print(
        f"\nfuzz: jobs in the store at the end, by status: {app.state.store.counts()}; "
        f"jobs of the stateful scenarios, by final status: {dict(SCENARIO_JOBS)}; dispatcher alive: {alive}"
    )
    store.close()


def checks(case) -> dict:
    """All checks but `positive_data_acceptance`; for the scene body also not `negative_data_rejection`:
    the scene is validated as `owcsim run` validates it (pydantic, lax), which takes `false` or "2.5"
    where the JSON Schema says number, as the command line does."""
    left_out = [schemathesis.checks.positive_data_acceptance]
    if case.method.upper() == "POST" and case.path in ("/v1/jobs", "/v1/preflight"):  # both take the scene body
        left_out.append(schemathesis.checks.negative_data_rejection)
    return {"excluded_checks": left_out}


@schema.parametrize()
@settings(max_examples=EXAMPLES, deadline=None, suppress_health_check=list(HealthCheck), print_blob=True)
def test_api(case):
    case.call_and_validate(**checks(case))


class Workflows(schema.as_state_machine()):
    """Sequences that follow the OpenAPI links: submit (the documented example), then get, cancel, results.

    Hypothesis replays a scenario (to shrink it, or to check a failure) and requires the
    replay to draw the same choices; which links it can follow depends on the answers
    (202 or 429, a job queued or finished). So every scenario starts from an empty job
    store, and a submitted job is waited for until it ends: the answers depend on the
    requests only, never on timing or on earlier scenarios.
    """

    def setup(self):
        with sqlite3.connect(DB, timeout=30) as con:
            con.execute("DELETE FROM job_documents")
            con.execute("DELETE FROM jobs")
        con.close()

    def after_call(self, response, case):
        super().after_call(response, case)
        if case.method.upper() == "POST" and case.path == "/v1/jobs" and response.status_code in (200, 202):
            job_id = response.json()["id"]
            deadline = time.monotonic() + 60
            while (job := app.state.store.get(job_id)) is not None and job.status in ("queued", "running"):
                assert time.monotonic() < deadline, f"fuzz job {job_id} still {job.status} after 60 s"
                time.sleep(0.02)
            SCENARIO_JOBS[job.status if job is not None else "gone"] += 1

    def validate_response(self, response, case, additional_checks=(), **kwargs):
        case.validate_response(response, **checks(case))


TestWorkflows = Workflows.TestCase
TestWorkflows.settings = settings(
    max_examples=max(5, EXAMPLES // 4), stateful_step_count=6, deadline=None, suppress_health_check=list(HealthCheck)
)
