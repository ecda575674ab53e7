# Build: the release binary.
FROM rust:1-bookworm AS build
WORKDIR /src
COPY Cargo.toml Cargo.lock ./
COPY server server
COPY benches benches
COPY tests tests
RUN cargo build --release --locked --bin lasertag

# Run: the binary, the maps and the web client, as a non-root user.
FROM debian:bookworm-slim
RUN useradd --system --uid 10001 --home /app lasertag
WORKDIR /app
COPY --from=build /src/target/release/lasertag /usr/local/bin/lasertag
COPY maps maps
COPY web web
USER lasertag
EXPOSE 8080
ENV LASERTAG_ADDR=0.0.0.0:8080
CMD ["lasertag", "serve"]
