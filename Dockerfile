# One image for every wallmap service; docker-compose.yml picks the subcommand.
FROM python:3.11-slim

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1

WORKDIR /app
COPY pyproject.toml README.md ./
COPY wallmap ./wallmap
COPY common ./common
COPY services ./services
RUN pip install . \
    && useradd --create-home --uid 1000 wallmap \
    && mkdir -p /data && chown wallmap /data

USER wallmap
VOLUME ["/data"]
ENTRYPOINT ["wallmap"]
CMD ["--help"]
