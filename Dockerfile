# The tslg image: the command-line tool, the coordinator and the worker.
# Everything is fetched and compiled at build time; nothing is downloaded
# when a container runs.
FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bins

# python3: the documented external vehicles (examples/python) and user
# cases' programs run in the worker's container.
FROM debian:bookworm-slim
RUN apt-get update \
    && apt-get install -y --no-install-recommends ca-certificates python3 \
    && rm -rf /var/lib/apt/lists/* \
    && groupadd --system --gid 10001 tslg \
    && useradd --system --uid 10001 --gid 10001 --create-home --home-dir /var/lib/tslg tslg \
    && mkdir -p /var/lib/tslg/data && chown tslg /var/lib/tslg/data
COPY --from=build /src/target/release/tslg /src/target/release/tslg-server /src/target/release/tslg-worker /usr/local/bin/
COPY --from=build /src/examples /usr/local/share/tslg/examples
# A numeric user, so that Kubernetes' runAsNonRoot can check it.
USER 10001:10001
WORKDIR /var/lib/tslg
ENV TSLG_BIND=0.0.0.0:8080 \
    TSLG_DATABASE_URL=sqlite:///var/lib/tslg/data/tslg.sqlite
EXPOSE 8080
CMD ["tslg-server"]
