"""gunicorn entry point, configured by environment variables (see rating_app.create_app):

    RATING_MANIFEST=stimuli/manifest.csv RATING_DATABASE_URL=postgresql://USER@HOST/DB RATING_ADMIN_TOKEN=... \\
        gunicorn -w 4 -k gthread --threads 16 --preload -b 127.0.0.1:8000 rating_app.wsgi:app

bound to loopback behind the proxy (docs/hosting.md): reached directly, a client could set its own
X-Forwarded-For and get round the per-address limits that RATING_PROXY_COUNT trusts the proxy for. With
`--preload` the master builds the app once and the workers share its pages, the video cache among them:
create_app leaves no database connection open for a worker to inherit.

A bad setting (no RATING_MANIFEST, a bad number, an unreachable database, a variable named as before the RATING_
prefix) prints one line and exits with gunicorn's "app failed to load" code (4): gunicorn then stops instead of
respawning the worker forever, as it does for any other exit code.
"""

import sys

from gunicorn.arbiter import Arbiter

from moglow_eval.core.cli import imports_done

from . import AppError, create_app

try:
    app = create_app()
except AppError as e:  # a clear line in the server log instead of a traceback
    print(f"error: {e}", file=sys.stderr, flush=True)
    raise SystemExit(Arbiter.APP_LOAD_ERROR) from None
# The app and its imports live as long as the server: frozen, the workers' collections neither walk them nor, with
# --preload, write to the pages each worker shares with the master that built them.
imports_done()
