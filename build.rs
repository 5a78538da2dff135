//! Puts the board's memory layout on the linker path and names the firmware binary's link
//! scripts, only for the bare-metal firmware build: `src/board/g071/memory.x` (the
//! NUCLEO-G071RB, feature `g071`), `src/board/pico/memory.x` (the Raspberry Pi Pico, feature
//! `pico`) or `src/board/bmcu/memory.x` (the BMCU-C, feature `bmcu`), as `board-memory.x`, which
//! the root `memory.x` includes.

use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=src/board/g071/memory.x");
    println!("cargo:rerun-if-changed=src/board/pico/memory.x");
    println!("cargo:rerun-if-changed=src/board/bmcu/memory.x");
    println!("cargo:rerun-if-changed=build.rs");
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let pico = env::var_os("CARGO_FEATURE_PICO").is_some();
    let bmcu = env::var_os("CARGO_FEATURE_BMCU").is_some();
    let memory = if pico {
        "src/board/pico/memory.x"
    } else if bmcu {
        "src/board/bmcu/memory.x"
    } else {
        "src/board/g071/memory.x"
    };
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(memory, out.join("board-memory.x")).expect("the memory layout is readable and OUT_DIR writable");
    println!("cargo:rustc-link-search={}", out.display());
    println!("cargo:rustc-link-arg-bins=--nmagic");
    // cortex-m-rt's, or qingke-rt's on the BMCU-C.
    println!("cargo:rustc-link-arg-bins=-Tlink.x");
    if pico {
        // embassy-rp's: places boot2 first in the flash.
        println!("cargo:rustc-link-arg-bins=-Tlink-rp.x");
    }
    if !bmcu {
        println!("cargo:rustc-link-arg-bins=-Tdefmt.x");
    }
}
