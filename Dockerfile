# Build: the release binary. The toolchain is pinned (the one the project is tested with)
# and the lock file pins every dependency, so a rebuild gives the same binary.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
# The workspace's crates (the server, the core, the policy runtime, the lab, and the Python
# engine, which is not built here but is a member cargo reads); cargo reads every target the
# manifest declares, and the benchmarks are declared by name.
COPY server server
COPY core core
COPY policy policy
COPY lab lab
COPY native native
COPY benches benches
# The registry and target/ are build caches (BuildKit, podman): a change under server/
# recompiles the workspace's crates, not their 160 dependencies. A cache is not part of the layer, so the
# binary is copied out of it.
RUN --mount=type=cache,target=/usr/local/cargo/registry \
    --mount=type=cache,target=/src/target \
    cargo build --release --locked --bin lasertag \
 && strip --strip-debug target/release/lasertag \
 && cp target/release/lasertag /usr/local/bin/lasertag

# Run: only the binary, the maps and the web client, as a non-root user. The same Debian
# release as the builder, so the binary's glibc is there; nothing else is installed (the
# health check is the binary's own `healthcheck` command, so no curl).
FROM debian:bookworm-slim
# A fixed uid and gid (10001, outside the system range) with no login shell.
RUN groupadd --gid 10001 lasertag \
 && useradd --uid 10001 --gid 10001 --no-create-home --home-dir /app \
      --shell /usr/sbin/nologin lasertag
WORKDIR /app
COPY --from=build /usr/local/bin/lasertag /usr/local/bin/lasertag
COPY maps maps
COPY web web
# The history database (SQLite) lives in a volume, owned by the user that writes it.
RUN mkdir /app/data && chown lasertag:lasertag /app/data
VOLUME /app/data
USER lasertag
# HTTP and WebSockets over TCP, WebTransport over UDP, on the same port.
EXPOSE 8080/tcp 8080/udp
# Listen on every interface inside the container; publish the port with `-p`.
ENV LASERTAG_ADDR=0.0.0.0:8080 \
    LASERTAG_MAPS=/app/maps \
    LASERTAG_WEB=/app/web \
    LASERTAG_DATA=/app/data
HEALTHCHECK --interval=30s --timeout=5s --start-period=10s --retries=3 \
  CMD ["lasertag", "healthcheck"]
# SIGTERM (docker stop) shuts down gracefully: clients get `finished` and a close within 5 s.
STOPSIGNAL SIGTERM
CMD ["lasertag", "serve"]
