"""REST API: routers per resource under ``app.api.routes``, assembled by :func:`app.api.main.create_app`."""
