"""The SQLite job store: WAL, order, run tokens that keep stale workers out, restart bookkeeping."""

import sqlite3

import pytest

from owcsim.server.store import IdempotencyConflict, JobStore, QueueFull


def _submit(store, n=1, **kw):
    out = []
    for i in range(n):
        args = dict(
            owner="",
            scene_json=f'{{"x": {i}}}',
            name=f"j{i}",
            request_hash=str(i),
            idempotency_key=None,
            max_queued=100,
        )
        args.update(kw)
        out.append(store.submit(**args)[0])
    return out


def test_one_file_in_wal_mode_reopened_intact(tmp_path):
    path = tmp_path / "sub" / "jobs.sqlite"
    store = JobStore(path)
    job = _submit(store)[0]
    store.close()
    assert sqlite3.connect(path).execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    again = JobStore(path)
    assert again.get(job.id).name == "j0" and again.scene_json(job.id) == '{"x": 0}'


def test_claims_in_submission_order(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    jobs = _submit(store, 3)
    claimed = [store.claim_next()[0] for _ in range(3)]
    assert claimed == [j.id for j in jobs] and store.claim_next() is None
    assert all(store.get(j.id).status == "running" and store.get(j.id).attempts == 1 for j in jobs)


def test_a_stale_run_cannot_write(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    job = _submit(store)[0]
    _, token = store.claim_next()
    assert store.take_back_running("restart") == [job.id]  # token moves on
    assert not store.progress(job.id, token, 0.5, 10, 1, 0.1, 1.0)
    assert not store.finish(job.id, token, "succeeded", result_json="{}")
    assert store.run_state(job.id, token) == (False, False)
    row = store.get(job.id)
    assert row.status == "queued" and row.error == "restart" and not row.has_result
    _, token2 = store.claim_next()
    assert token2 > token and store.progress(job.id, token2, 0.5, 10, 1, 0.1, 1.0)
    assert store.finish(job.id, token2, "succeeded", result_json='{"ok": 1}')
    assert store.result_json(job.id) == b'{"ok": 1}' and store.get(job.id).fraction == 1.0


def test_settle_dead_worker_retries_then_fails(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    job = _submit(store)[0]
    _, t1 = store.claim_next()
    assert store.settle(job.id, t1, "killed", retries=1) == "queued"
    assert store.settle(job.id, t1, "killed", retries=1) is None  # already settled
    _, t2 = store.claim_next()
    assert store.settle(job.id, t2, "killed again", retries=1) == "failed"
    row = store.get(job.id)
    assert row.status == "failed" and row.error == "killed again" and row.crashes == 1 and row.attempts == 2


def test_cancel_requests(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    running, queued = _submit(store, 2)
    _, token = store.claim_next()
    assert store.request_cancel(queued.id, None).status == "cancelled"  # at once
    assert store.request_cancel(running.id, "someone-else") is None  # not theirs
    asked = store.request_cancel(running.id, None)
    assert asked.status == "running" and asked.cancel_requested  # the worker stops it
    assert store.run_state(running.id, token) == (True, True)
    assert store.settle(running.id, token, "stopped", retries=5) == "cancelled"
    assert store.claim_next() is None


def test_restart_cancels_jobs_whose_cancel_was_asked(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    a, b = _submit(store, 2)
    store.claim_next()
    store.claim_next()
    store.request_cancel(b.id, None)
    store.take_back_running("restart")
    assert store.get(a.id).status == "queued" and store.get(b.id).status == "cancelled"


def test_queue_limit_and_idempotency(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    _submit(store, 2, max_queued=2)
    with pytest.raises(QueueFull):
        _submit(store, 1, max_queued=2)
    first, created = store.submit(
        owner="a", scene_json="{}", name=None, request_hash="h", idempotency_key="k", max_queued=10
    )
    again, created2 = store.submit(
        owner="a", scene_json="{}", name=None, request_hash="h", idempotency_key="k", max_queued=10
    )
    assert created and not created2 and again.id == first.id
    with pytest.raises(IdempotencyConflict):
        store.submit(owner="a", scene_json="{}", name=None, request_hash="other", idempotency_key="k", max_queued=10)


def test_list_pages(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    jobs = _submit(store, 5)
    page, nxt = store.list(None, None, 2, None)
    assert [j.id for j in page] == [jobs[4].id, jobs[3].id] and nxt == jobs[3].id  # opaque: the last id
    page, nxt = store.list(None, ["queued"], 10, nxt)
    assert [j.id for j in page] == [j.id for j in jobs[2::-1]] and nxt is None
    assert store.counts() == {"queued": 5}
    with pytest.raises(KeyError):  # another owner's job is no cursor of this owner's listing
        store.list("someone-else", None, 2, jobs[3].id)


def test_restarts_count_toward_the_attempt_limit(tmp_path):
    store = JobStore(tmp_path / "j.sqlite")
    job = _submit(store)[0]
    for attempt in range(1, 4):
        store.claim_next()
        store.take_back_running("restart", max_attempts=3)
        assert store.get(job.id).status == ("queued" if attempt < 3 else "failed")
    assert "started 3 times" in store.get(job.id).error and store.claim_next() is None


def test_an_old_store_is_upgraded_in_place(tmp_path):
    path = tmp_path / "j.sqlite"
    con = sqlite3.connect(path)
    from owcsim.server import job_rows

    con.executescript(job_rows.SCHEMA)
    con.execute("PRAGMA user_version=1")
    con.execute("INSERT INTO jobs (id, owner, request_hash, status, created_at) VALUES ('a', '', 'h', 'queued', 0)")
    con.execute("INSERT INTO job_documents (job_id, scene) VALUES ('a', ?)", (job_rows.pack("{}"),))
    con.commit()
    con.close()
    store = JobStore(path, server=True)
    assert store.get("a").memory_bytes == 0 and store.claim_next()[0] == "a"
    store.close()
