# One image for every wallmap service; docker-compose.yml picks the subcommand.
FROM python:3.11-slim

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    NUMBA_CACHE_DIR=/opt/wallmap-kernels

WORKDIR /app
COPY pyproject.toml README.md ./
COPY wallmap ./wallmap
COPY common ./common
COPY services ./services
# The compiled loops (the detector's, the mapper's rooms) compiled as the image is built (numba
# caches them where NUMBA_CACHE_DIR says), so no container spends its first seconds compiling.
RUN pip install . \
    && python -c 'from wallmap.common.compiled import compile_all; compile_all()' \
    && useradd --create-home --uid 1000 wallmap \
    && chown -R wallmap /opt/wallmap-kernels \
    && mkdir -p /data && chown wallmap /data

USER wallmap
VOLUME ["/data"]
ENTRYPOINT ["wallmap"]
CMD ["--help"]
