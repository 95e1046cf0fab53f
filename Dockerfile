# gngdt services image: capture, learner and logger all run from this one image (`gngdt <service>`).
# Everything is installed at build time; nothing is downloaded when a container runs.
FROM python:3.11-slim

ENV PYTHONUNBUFFERED=1 \
    PIP_NO_CACHE_DIR=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    NUMBA_CACHE_DIR=/var/cache/gngdt/numba \
    XDG_CONFIG_HOME=/var/cache/gngdt/config

WORKDIR /app
COPY pyproject.toml README.md LICENSE ./
COPY gngdt_core ./gngdt_core
COPY schemas ./schemas
COPY gngdt_io ./gngdt_io
COPY gngdt_eval ./gngdt_eval
COPY services ./services
COPY config ./config
COPY gngdt ./gngdt
RUN pip install . \
    && mkdir -p "$NUMBA_CACHE_DIR" "$XDG_CONFIG_HOME" /recordings /out \
    # Compile the numba kernels once at build time so a container starts learning at once.
    && python -c "from gngdt.core import GNGDT; from gngdt.eval.synthetic import make_data2; p, c, _ = make_data2(n_points=2000, random_state=0); GNGDT(max_nodes=50, random_state=0).partial_fit(p, c, n_steps=2000)" \
    && chmod -R a+rwX /var/cache/gngdt /out

# Unprivileged by default; compose runs services as the invoking user (GNGDT_UID/GNGDT_GID).
USER nobody
VOLUME ["/recordings", "/out"]
ENTRYPOINT ["gngdt"]
CMD ["--help"]
