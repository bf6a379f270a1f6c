"""gunicorn entry point, configured by environment variables (see rating_app.create_app):

    RATING_MANIFEST=stimuli/manifest.csv DATABASE_URL=postgresql://USER@HOST/DB ADMIN_TOKEN=... \\
        gunicorn -w 4 -k gthread --threads 8 -b 0.0.0.0:8000 rating_app.wsgi:app
"""
import sys

from . import AppError, create_app

try:
    app = create_app()
except AppError as e:                      # a clear line in the server log instead of a traceback
    print(f"error: {e}", file=sys.stderr)
    raise SystemExit(2) from None
