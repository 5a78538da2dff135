# Reproducible firmware build for every board (NUCLEO-G071RB, also for N20 encoder motors;
# Raspberry Pi Pico; the BMCU-C's CH32V203), and a flashing image.
#
#   docker build -t mmu-firmware .
#       builds every firmware and an image with probe-rs (compiled once: ~10 min on 2 cores)
#   docker run --rm -it --privileged -v /dev/bus/usb:/dev/bus/usb mmu-firmware
#       flashes the NUCLEO over its ST-LINK (USB passthrough), runs the firmware and prints its
#       defmt log until Ctrl-C; extra arguments replace the ELF path
#   docker run --rm -it --privileged -v /dev/bus/usb:/dev/bus/usb mmu-firmware \
#           --chip RP2040 /firmware/mmu-firmware-pico.elf
#       the same for a Pico behind a debug probe (a second Pico running debugprobe, on SWD)
#   DOCKER_BUILDKIT=1 docker build --target firmware --output dist .
#       only the firmware: writes dist/mmu-firmware-{g071,g071-n20,pico,bmcu}.elf (the BMCU-C's is
#       flashed with wchisp, not probe-rs: book/src/bmcu-c.md)
#       (`--output` needs BuildKit: the default since Docker Engine 23.0, DOCKER_BUILDKIT=1
#       before it; or `docker buildx build ...` with the buildx plugin)
#
# The build steps are not written here but in scripts/build-firmware.sh, which CI (.ci/run) runs
# too: what this image builds is what CI checks.

# Pinned: the same Rust release as rust-toolchain.toml (1.95.0) and the CI machines.
ARG RUST_IMAGE=rust:1.95.0-bookworm
ARG PROBE_RS_VERSION=0.32.0

# ---- build: the firmware ELF ----
FROM ${RUST_IMAGE} AS build
ENV RUSTUP_TOOLCHAIN=1.95.0 \
    CARGO_TERM_COLOR=never \
    DEFMT_LOG=info
WORKDIR /src
COPY . .
RUN bash scripts/build-firmware.sh g071 /out && bash scripts/build-firmware.sh g071-n20 /out \
    && bash scripts/build-firmware.sh pico /out && bash scripts/build-firmware.sh bmcu /out

# ---- firmware: just the ELF, for `docker build --target firmware --output dist .` ----
FROM scratch AS firmware
COPY --from=build /out/mmu-firmware-g071.elf /out/mmu-firmware-g071-n20.elf \
    /out/mmu-firmware-pico.elf /out/mmu-firmware-bmcu.elf /

# ---- flash (default): probe-rs and the firmware ----
FROM ${RUST_IMAGE} AS flash
ARG PROBE_RS_VERSION
# The probe.rs install guide lists these for Debian; the USB access itself needs none of them.
RUN apt-get update \
    && apt-get install -y --no-install-recommends pkg-config libudev-dev \
    && rm -rf /var/lib/apt/lists/*
RUN cargo install probe-rs-tools --version "${PROBE_RS_VERSION}" --locked \
    && rm -rf /usr/local/cargo/registry /usr/local/cargo/git
COPY --from=build /out/mmu-firmware-g071.elf /out/mmu-firmware-g071-n20.elf \
    /out/mmu-firmware-pico.elf /out/mmu-firmware-bmcu.elf /firmware/
ENTRYPOINT ["probe-rs", "run"]
CMD ["--chip", "STM32G071RBTx", "/firmware/mmu-firmware-g071.elf"]
