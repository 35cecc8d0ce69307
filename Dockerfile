# syntax=docker/dockerfile:1
# Build: docker build -t robocal .
# Run:   docker run --rm -p 8080:8080 -v robocal-data:/data robocal
#        (the first time: docker run --rm -v robocal-data:/data robocal token create --name admin --scopes admin)
# The server binds 0.0.0.0 inside the container, so every /v1 request needs a bearer token.

FROM rust:1.95-slim-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock rustfmt.toml ./
# The workspace's members (the numerical core and the Python bindings): cargo loads every member's
# manifest even to build one binary. scripts/dockerfile_check.sh checks that this COPY set builds.
COPY crates ./crates
COPY src ./src
COPY benches ./benches
COPY migrations ./migrations
COPY openapi ./openapi
RUN cargo build --release --locked --bin robocal

FROM debian:bookworm-slim AS runtime
RUN groupadd --system --gid 10001 robocal \
    && useradd --system --uid 10001 --gid 10001 --home-dir /data --shell /usr/sbin/nologin robocal \
    && mkdir -p /data && chown 10001:10001 /data
COPY --from=build /src/target/release/robocal /usr/local/bin/robocal
USER 10001:10001
WORKDIR /data
VOLUME ["/data"]
ENV ROBOCAL_DB=/data/robocal.db \
    ROBOCAL_BIND=0.0.0.0:8080 \
    RUST_LOG=info
EXPOSE 8080
STOPSIGNAL SIGTERM
ENTRYPOINT ["/usr/local/bin/robocal"]
CMD ["serve"]
