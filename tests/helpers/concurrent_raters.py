"""A crowd of raters in threads against one app, for the tests that check targets under concurrent sessions."""

import threading


def run_raters(app, answer, n=8, timeout=300):
    """`n` raters start at once; each opens sessions until the study is full (409) and answers every trial it is
    served with answer(client, token, trial). Returns the errors they raised, as reprs (the caller asserts)."""
    barrier, errors = threading.Barrier(n), []

    def rater():
        c = app.test_client()
        barrier.wait()
        try:
            while True:
                r = c.post("/api/sessions", json={})
                if r.status_code == 409:
                    return
                token = r.json["session"]
                while True:
                    r = c.get(f"/api/sessions/{token}/next")
                    if r.status_code != 200 or r.json.get("done"):
                        break
                    answer(c, token, r.json["trial"])
        except Exception as e:  # noqa: BLE001 - returned to the test, which reports it
            errors.append(repr(e))

    threads = [threading.Thread(target=rater) for _ in range(n)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout)
    return errors


def cover_mismatches(engine):
    """{key: (Cover row, count from the trials)} wherever the app's running counts (rating_app.store.db.Cover) differ
    from counting the trials; {} when they agree, as they must after any crowd, crash or expiry."""
    from sqlalchemy import select

    from rating_app.store.db import Cover, trial_cover

    with engine.connect() as conn:
        rows = {k: (a, h) for k, a, h in conn.execute(select(Cover.key, Cover.answered, Cover.held))}
        counted = trial_cover(conn)
    return {
        k: (rows.get(k), counted.get(k, (0, 0)))
        for k in rows.keys() | counted.keys()
        if rows.get(k, (0, 0)) != counted.get(k, (0, 0))
    }
