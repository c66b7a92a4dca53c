# srlab's service image: `srlab serve` (one uvicorn worker) as a non-root user.
#
#   docker compose up -d              # with PostgreSQL, see docker-compose.yml and README
#   docker build -t srlab .           # the image alone: SQLite in /data, see README
#
# Two stages: the first installs the locked dependencies with uv, the second holds only
# Python, the virtual environment and the source, without uv, compilers or the dev tools.
# Both stages use the same base, so the venv's interpreter path is the same in both.
ARG PYTHON_IMAGE=python:3.11-slim-bookworm

FROM ${PYTHON_IMAGE} AS build
# The uv the project is developed with, from PyPI (the Makefile also installs it with pip).
ARG UV_VERSION=0.13.9
RUN pip install --no-cache-dir --root-user-action=ignore "uv==${UV_VERSION}"
ENV UV_COMPILE_BYTECODE=1 \
    UV_LINK_MODE=copy \
    UV_PYTHON_DOWNLOADS=never \
    UV_PYTHON=/usr/local/bin/python3.11 \
    UV_PROJECT_ENVIRONMENT=/app/.venv
WORKDIR /app
# The dependencies first, in their own layer: a change to the code does not reinstall them.
COPY pyproject.toml uv.lock ./
RUN uv sync --frozen --no-dev --no-install-project
# Then srlab itself, editable: the migrations and alembic.ini are found beside the source
# (server/persistence/migrate.py's find_migrations; a wheel carries them as shared data).
COPY README.md alembic.ini ./
COPY core core
COPY server server
COPY migrations migrations
COPY web web
RUN uv sync --frozen --no-dev
# uv compiles site-packages; srlab's own modules are compiled here, since the service's
# user cannot write beside them (each start would compile them again: about 1 s of CPU).
RUN .venv/bin/python -m compileall -q core server migrations

FROM ${PYTHON_IMAGE}
# /data holds the SQLite database when no SRLAB_DATABASE_URL is given (the image alone:
# `docker run -v srlab-data:/data ...`); compose points the service at PostgreSQL instead.
RUN useradd --system --uid 10001 --user-group --create-home --home-dir /home/srlab srlab \
    && install -d -o srlab -g srlab /data
COPY --from=build /app /app
WORKDIR /app
ENV PATH=/app/.venv/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    NUMBA_CACHE_DIR=/home/srlab/.cache/numba \
    MPLCONFIGDIR=/home/srlab/.cache/matplotlib \
    SRLAB_DATABASE_URL=sqlite:////data/srlab.db \
    SRLAB_HOST=0.0.0.0 \
    SRLAB_PORT=8000 \
    SRLAB_VISER_PORT=8080
USER srlab
# Compile the sensing kernel now (numba caches it in NUMBA_CACHE_DIR), so a container does
# not spend its first seconds compiling.
RUN python -c "from core.sim.world import PymunkWorld; PymunkWorld().reset(0, 0)"
EXPOSE 8000 8080
# The same command as the compose file's healthcheck (tests/deploy checks they agree).
HEALTHCHECK --interval=10s --timeout=5s --start-period=30s --retries=3 \
    CMD ["python", "-m", "server.healthcheck"]
# Migrates the database to the newest schema and seeds it, then serves. It binds 0.0.0.0
# (SRLAB_HOST above), so it refuses to start without SRLAB_TOKEN. SIGTERM interrupts the
# runs cleanly within a few seconds; they stay resumable.
CMD ["srlab", "serve"]
