# lashscope REST API: `docker build -t lashscope .`, then
#   docker run --rm -v lashscope-data:/data lashscope lashscope keys create --scope admin   # prints the API key once
#   docker run -p 8000:8000 -v lashscope-data:/data lashscope
# Same command as on a workstation (`lashscope serve`); data (SQLite + files) lives in the /data volume.
# Listening on 0.0.0.0, the server refuses to start without an API key in the store, unless
# LASHSCOPE_INSECURE=1 (something in front of it authenticates). Host names other than localhost
# must be allowed: -e LASHSCOPE_ALLOWED_HOSTS=lashscope.example.org
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    MPLBACKEND=Agg \
    LASHSCOPE_DATA_DIR=/data \
    LASHSCOPE_DBC_DIR=/opt/lashscope/dbc \
    NUMBA_CACHE_DIR=/tmp/numba-cache

WORKDIR /opt/lashscope
COPY pyproject.toml README.md ./
COPY app ./app
COPY sim ./sim
COPY dbc ./dbc
RUN pip install . \
    && useradd --system --uid 10001 --home-dir /data --shell /usr/sbin/nologin lashscope \
    && mkdir -p /data \
    && chown lashscope:lashscope /data

USER lashscope
VOLUME ["/data"]
EXPOSE 8000
HEALTHCHECK --interval=30s --timeout=5s --start-period=20s \
    CMD python -c "import urllib.request; urllib.request.urlopen('http://127.0.0.1:8000/health', timeout=4)"
# 0.0.0.0 inside the container so the published port reaches it; the default outside a container is 127.0.0.1.
# /health answers without a key, so the health check needs none.
CMD ["lashscope", "serve", "--host", "0.0.0.0", "--port", "8000"]
