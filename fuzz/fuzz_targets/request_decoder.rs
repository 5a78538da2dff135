//! Feeds arbitrary bytes to the unit's [`RequestDecoder`]; the checks are in `common/decoder.rs`.

#![no_main]

use libfuzzer_sys::fuzz_target;
use mmu_protocol::RequestDecoder;

#[path = "common/decoder.rs"]
mod decoder;

fuzz_target!(|data: &[u8]| decoder::check::<RequestDecoder>(data));
